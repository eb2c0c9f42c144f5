"""Which ROS 2 middleware, and how far its discovery reaches, by ROS 2's own variables:
`RMW_IMPLEMENTATION` (rmw_zenoh_cpp: rmw_zenoh; unset or any DDS rmw: DDS, ROS 2's default),
`ROS_AUTOMATIC_DISCOVERY_RANGE` (SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT) and `ROS_STATIC_PEERS`
turned into Cyclone DDS configuration as rmw_cyclonedds does; `CYCLONEDDS_URI`, when set, is
Cyclone's own and taken as it is."""

from __future__ import annotations

import os
from xml.sax.saxutils import quoteattr

from beyond_self.core.errors import InputError, unknown

DDS, ZENOH = "dds", "zenoh"
RMWS = (DDS, ZENOH)
# RMW_IMPLEMENTATION values -> the middleware it speaks
IMPLEMENTATIONS = {
    "rmw_fastrtps_cpp": DDS,
    "rmw_fastrtps_dynamic_cpp": DDS,
    "rmw_cyclonedds_cpp": DDS,
    "rmw_connextdds": DDS,
    "rmw_gurumdds_cpp": DDS,
    "rmw_zenoh_cpp": ZENOH,
}
RANGES = ("SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT")


def choose(flag: str | None = None) -> str:
    """`flag` (`--ros2-rmw`) if given, else what $RMW_IMPLEMENTATION names (DDS when unset)."""
    if flag:
        if flag not in RMWS:
            raise unknown("ROS 2 middleware", flag, RMWS)
        return flag
    name = os.environ.get("RMW_IMPLEMENTATION", "").strip()
    if not name:
        return DDS
    if name not in IMPLEMENTATIONS:
        raise unknown("RMW_IMPLEMENTATION", name, tuple(IMPLEMENTATIONS))
    return IMPLEMENTATIONS[name]


def discovery_range() -> str:
    """$ROS_AUTOMATIC_DISCOVERY_RANGE (SUBNET when unset; ROS_LOCALHOST_ONLY=1 as LOCALHOST)."""
    value = os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").strip().upper()
    if not value:
        return "LOCALHOST" if os.environ.get("ROS_LOCALHOST_ONLY", "") == "1" else "SUBNET"
    if value not in RANGES:
        raise unknown("ROS_AUTOMATIC_DISCOVERY_RANGE", value, RANGES)
    return value


def static_peers() -> list[str]:
    """$ROS_STATIC_PEERS: addresses separated by ';'."""
    return [p.strip() for p in os.environ.get("ROS_STATIC_PEERS", "").split(";") if p.strip()]


def cyclone_config() -> str | None:
    """Cyclone DDS configuration for the discovery range and static peers, or None: Cyclone's
    own ($CYCLONEDDS_URI, or its defaults for SYSTEM_DEFAULT). LOCALHOST: the loopback
    interface, no multicast, unicast discovery to 127.0.0.1; OFF: nobody outside the process;
    SUBNET: multicast discovery, as Cyclone does by default."""
    if os.environ.get("CYCLONEDDS_URI", "").strip():
        return None
    reach = discovery_range()
    if reach == "SYSTEM_DEFAULT":
        return None
    peers = static_peers()
    general = ""
    if reach in ("LOCALHOST", "OFF"):
        general = (
            '<General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>'
            "<AllowMulticast>false</AllowMulticast></General>"
        )
        if reach == "LOCALHOST":
            peers = ["127.0.0.1", *peers]
    for peer in peers:
        if any(c in peer for c in "<>&\"'"):
            raise InputError(f"ROS_STATIC_PEERS holds {peer!r}; valid: addresses separated by ';'")
    listed = "".join(f"<Peer address={quoteattr(p)}/>" for p in peers)
    discovery = (
        "<Discovery><ParticipantIndex>auto</ParticipantIndex>"
        f"<MaxAutoParticipantIndex>32</MaxAutoParticipantIndex><Peers>{listed}</Peers></Discovery>"
        if peers
        else ""
    )
    return f'<CycloneDDS><Domain Id="any">{general}{discovery}</Domain></CycloneDDS>'
