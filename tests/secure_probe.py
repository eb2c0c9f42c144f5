"""Probe of a secure router's rules: `python tests/secure_probe.py KEYSTORE FOREIGN_KEYSTORE`;
`python tests/secure_probe.py watch KEY` prints `present` or `absent` every 0.2 s: whether a
liveliness token matches KEY, as the router the bus (from the environment) joins knows it now.

Run inside the namespace of a running `beyond router --secure KEYSTORE`. It opens sessions with
several identities and prints one JSON line of what each received. Denials are judged by order,
never by waiting: a message is known not to have been delivered once a later message on the same
links (allowed, sent after it by the same session) has arrived.

- `counter` (tools) counts everything on beyond/**; `speech` counts descriptions and serves its
  health; `describer` subscribes to words (allowed) and to the camera (not allowed).
- ingest puts skeleton frames (allowed: the counter sees them, which shows the counter works).
- the describer puts on sensors/** and affordance/** (denied), then a description (allowed): when
  the counter has the description, it would already have the earlier ones.
- ingest puts camera frames; once the counter has them all, the reasoner puts words: when the
  describer has the words, it would already have any camera frame the router forwarded it.
- a second tools session puts a fake description (denied), then queries speech's health: when it
  has the reply, speech would already have the fake description.
A session receives its own puts locally whatever the router says: only others' payloads count.
- intruders (no certificate; a certificate from another CA) open peer sessions that keep trying
  the router, subscribe to beyond/** and put; they never get a link.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import zenoh

from beyond_self.runtime.bus.config import BusConfig, zenoh_config

ROOT = "beyond/robot"
ROUTER = "tls/127.0.0.1:7447"
WAIT_S = 60.0


class Count:
    """Samples per key, with a condition to wait on."""

    def __init__(self) -> None:
        self.keys: Counter[str] = Counter()
        self.payloads: list[bytes] = []
        self.cond = threading.Condition()

    def __call__(self, sample: Any) -> None:
        with self.cond:
            self.keys[str(sample.key_expr)] += 1
            self.payloads.append(sample.payload.to_bytes())
            self.cond.notify_all()

    def received(self) -> list[str]:
        with self.cond:
            return sorted({p.decode() for p in self.payloads})

    def wait(self, key: str, n: int = 1) -> None:
        deadline = time.monotonic() + WAIT_S
        with self.cond:
            while self.keys[key] < n:
                if time.monotonic() > deadline:
                    raise SystemExit(f"probe: {key} never arrived ({dict(self.keys)})")
                self.cond.wait(0.5)


def session(keystore: Path, identity: str) -> Any:
    return zenoh.open(zenoh_config(BusConfig(mode="client", secure=keystore, identity=identity)))


def intruder(tls: dict[str, Any]) -> Any:
    """A peer that keeps trying the router in the background (open() does not wait for it)."""
    config = zenoh.Config()
    for key, value in {
        "mode": "peer",
        "scouting/multicast/enabled": False,
        "listen/endpoints": [],
        "connect/endpoints": [ROUTER],
        "connect/timeout_ms": 0,
        "connect/exit_on_failure": False,
        "connect/retry": {"period_init_ms": 100, "period_max_ms": 500},
        "transport/link/tls": tls,
    }.items():
        config.insert_json5(key, json.dumps(value))
    return zenoh.open(config)


def main(keystore: Path, foreign: Path) -> int:
    zenoh.init_log_from_env_or("error")
    counter = session(keystore, "tools")
    seen = Count()
    counter.declare_subscriber(f"{ROOT}/**", seen)

    speech = session(keystore, "speech")
    speech_seen = Count()
    speech.declare_subscriber(f"{ROOT}/language/description", speech_seen)
    speech.declare_queryable(f"{ROOT}/health/speech", lambda q: q.reply(q.key_expr, b"ok"))

    describer = session(keystore, "describer")
    describer_seen = Count()
    describer.declare_subscriber(f"{ROOT}/language/words", describer_seen)
    describer.declare_subscriber(f"{ROOT}/sensors/camera/raw", describer_seen)

    intruders: dict[str, dict[str, Any]] = {
        "no-certificate": {"root_ca_certificate": str(keystore / "ca.crt")},
        "other-ca": {
            "root_ca_certificate": str(foreign / "ca.crt"),
            "connect_certificate": str(foreign / "describer.crt"),
            "connect_private_key": str(foreign / "describer.key"),
            "verify_name_on_connect": False,
        },
    }
    intruder_seen: dict[str, Count] = {}
    intruder_sessions = {}
    for name, tls in intruders.items():
        s = intruder(tls)
        intruder_seen[name] = Count()
        s.declare_subscriber(f"{ROOT}/**", intruder_seen[name])
        intruder_sessions[name] = s

    ingest = session(keystore, "ingest")
    reasoner = session(keystore, "reasoner")
    # subscriptions must have reached the router before the first put: wait for the counter's
    # own view of a put that only ingest may make
    skeleton = f"{ROOT}/sensors/skeleton"
    deadline = time.monotonic() + WAIT_S
    while seen.keys[skeleton] == 0 and time.monotonic() < deadline:
        ingest.put(skeleton, b"real-skeleton")
        with seen.cond:
            seen.cond.wait(0.2)
    seen.wait(skeleton)
    deadline = time.monotonic() + WAIT_S
    while speech_seen.keys[f"{ROOT}/language/description"] == 0 and time.monotonic() < deadline:
        describer.put(f"{ROOT}/language/description", b"real-description")
        with speech_seen.cond:
            speech_seen.cond.wait(0.2)
    speech_seen.wait(f"{ROOT}/language/description")

    for name, s in intruder_sessions.items():  # puts from outside, while the bus is busy
        s.put(f"{ROOT}/language/description", f"fake-{name}".encode())
        s.put(skeleton, f"fake-{name}".encode())
    for name in intruder_sessions:  # each hears its own puts (locally), however loaded
        intruder_seen[name].wait(skeleton)

    before = dict(seen.keys)
    describer.put(skeleton, b"fake-describer-skeleton")
    describer.put(f"{ROOT}/sensors/camera/raw", b"fake-describer-camera")
    describer.put(f"{ROOT}/affordance/prediction", b"fake-describer-affordance")
    describer.put(f"{ROOT}/language/description", b"real-description-2")
    seen.wait(f"{ROOT}/language/description", before.get(f"{ROOT}/language/description", 0) + 1)

    camera = f"{ROOT}/sensors/camera/raw"
    frames = 20
    n0 = seen.keys[camera]
    for i in range(frames):
        ingest.put(camera, f"camera-{i}".encode())
    seen.wait(camera, n0 + frames)
    reasoner.put(f"{ROOT}/language/words", b"real-words")
    describer_seen.wait(f"{ROOT}/language/words")

    tool = session(keystore, "tools")
    tool.put(f"{ROOT}/language/description", b"fake-tools-description")
    replies = list(tool.get(f"{ROOT}/health/speech", timeout=10))
    answered = [r.ok.payload.to_bytes().decode() for r in replies if r.ok is not None]

    intruder_links = {
        name: len(list(s.info.routers_zid())) + len(list(s.info.peers_zid()))
        for name, s in intruder_sessions.items()
    }
    result = {
        "counter": seen.received(),
        "speech": speech_seen.received(),
        "describer": describer_seen.received(),
        "health_reply": answered,
        "intruders": {n: c.received() for n, c in intruder_seen.items()},
        "intruder_links": intruder_links,
    }
    print(json.dumps(result), flush=True)
    for s in [counter, tool, speech, describer, ingest, reasoner, *intruder_sessions.values()]:
        s.close()
    return 0


def watch(key: str) -> int:
    from beyond_self.runtime.bus.config import load_config

    zenoh.init_log_from_env_or("error")
    bus = zenoh.open(zenoh_config(load_config()))
    while True:
        replies = [r for r in bus.liveliness().get(key, timeout=1.0) if r.ok is not None]
        print("present" if replies else "absent", flush=True)
        time.sleep(0.2)


if __name__ == "__main__":
    if sys.argv[1] == "watch":
        raise SystemExit(watch(sys.argv[2]))
    raise SystemExit(main(Path(sys.argv[1]), Path(sys.argv[2])))
