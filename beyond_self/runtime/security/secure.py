"""Zenoh settings of a secure bus: mutual TLS on every link, the access rules on the router.

A secure bus has no peers: they would meet each other directly, past the router's rules. Every
process is a client of a router, or the router, over `tls/` only; the one CA trusted is the
keystore's (runtime/security/keystore.py), and the router requires a client certificate, whose
common name
is who the client is in its rules (runtime/security/acl.py). Host names are not verified: robots are
reached by address, and trust rests on the pinned CA, not on DNS. Certificates are checked first
(`keystore.check`): a bad one is one line naming the file, not a handshake Zenoh retries forever.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from beyond_self.core.errors import InputError
from beyond_self.runtime.security import keystore


def router_listen(port: int, *, loopback: bool = False) -> str:
    """Where a secure router listens: every interface (a side that other machines reach), or
    loopback only (everything on one machine)."""
    return f"tls/127.0.0.1:{port}" if loopback else f"tls/[::]:{port}"


def router_connect(port: int) -> str:
    """Where a secure client reaches the router on its own machine."""
    return f"tls/127.0.0.1:{port}"


def default_identity(mode: str) -> str:
    """Who a process is when nobody said: the router, or a read-only tool."""
    return "router" if mode == "router" else keystore.TOOLS


def check_endpoints(listen: list[str], connect: list[str]) -> None:
    plain = [e for e in listen + connect if not e.startswith("tls/")]
    if plain:
        raise InputError(
            f"a secure bus links only over TLS; endpoints {', '.join(plain)} are not tls/ "
            "(valid: tls/HOST:PORT)"
        )


def tls_settings(
    directory: Path, identity: str, mode: str, access_rules: Mapping[str, Any] | None = None
) -> dict[str, Any]:
    """Zenoh config entries (path -> value) for `identity` from the keystore in `directory`; a
    router's include its `access_rules` (services.registry.access_rules)."""
    ca, cert, key = keystore.check(directory, identity)
    tls: dict[str, Any] = {
        "root_ca_certificate": str(ca),
        "enable_mtls": True,
        "verify_name_on_connect": False,
        "close_link_on_expiration": True,
        "connect_certificate": str(cert),
        "connect_private_key": str(key),
        # any TLS listener, whatever the mode or where it was given, presents the identity's
        "listen_certificate": str(cert),
        "listen_private_key": str(key),
    }
    sets: dict[str, Any] = {"transport/link/tls": tls}
    if mode == "router":
        if access_rules is None:
            raise InputError(
                "a secure router needs the deployment's access rules: start it with "
                "`beyond router --secure DIR`"
            )
        sets["access_control"] = dict(access_rules)
    return sets
