"""The single source of truth for every message on the bus (versioned msgspec Structs) and for the
key expressions they travel on."""
