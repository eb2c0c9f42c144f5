"""The secure bus: keystore, certificates, access rules."""
