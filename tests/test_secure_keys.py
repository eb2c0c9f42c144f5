"""The keystore, the generated access rules, declarations enforced, and bad certificates.

Everything here runs without a network: a bad certificate must be caught before any link is
tried (one line naming the file, exit 2), and the rules are a pure function of the services'
declarations. The rules at work on a real router: tests/test_secure_netns.py.
"""

from __future__ import annotations

import datetime as dt
import os
import shutil
import stat
import subprocess
import time
from pathlib import Path

import pytest

from beyond_self.core.errors import InputError
from beyond_self.runtime.bus.config import BusConfig, load_config, zenoh_config
from beyond_self.runtime.bus.session import Bus
from beyond_self.runtime.security import acl, keystore
from beyond_self.runtime.service import Service
from beyond_self.schemas import Description, WordProbabilities
from beyond_self.services import registry
from beyond_self.services.launcher import BEYOND
from beyond_self.services.registry import SERVICES, service_class

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("keys") / "store"
    keystore.init(directory, registry.identities())
    return directory


def beyond(*args: str) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("BEYOND_")}
    return subprocess.run(
        [*BEYOND, *args],
        capture_output=True,
        text=True,
        timeout=60,
        env=env,
        cwd=REPO,
    )


def test_init_makes_one_certificate_per_identity_with_private_keys(store: Path) -> None:
    names = {e.name for e in keystore.show(store)}
    assert names == {"ca", *SERVICES, "tools", "router", "robot", "workstation"}
    assert stat.S_IMODE(store.stat().st_mode) == 0o700
    for key in store.glob("*.key"):
        assert stat.S_IMODE(key.stat().st_mode) == 0o600, key
    for name in names - {"ca"}:
        keystore.check(store, name)  # current, issued to the name, signed by the CA, key matches
    with pytest.raises(InputError, match="already holds a CA"):
        keystore.init(store, ["x"])


def test_keys_cli_show_lists_expiry_and_add_renews(store: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(store, copy)
    before = (copy / "speech.crt").read_bytes()
    added = beyond("keys", "add", "speech", "--dir", str(copy), "--days", "30")
    assert added.returncode == 0, added.stderr
    assert (copy / "speech.crt").read_bytes() != before
    shown = beyond("keys", "show", "--dir", str(copy))
    assert shown.returncode == 0, shown.stderr
    line = next(x for x in shown.stdout.splitlines() if x.startswith("speech "))
    soon = (dt.datetime.now(dt.UTC) + dt.timedelta(days=30)).strftime("%Y-%m-")
    assert "valid" in line and soon in line


def test_rules_follow_the_declarations() -> None:
    rules = registry.access_rules()
    assert rules["default_permission"] == "deny" and rules["enabled"] is True
    by_id = {r["id"]: r for r in rules["rules"]}
    describer_puts = by_id["describer-out-ingress"]["key_exprs"]
    assert "beyond/robot/language/description" in describer_puts
    assert not any("sensors" in k or "affordance" in k for k in describer_puts)
    # every rule names the robot the identity is bound to, never any robot
    assert not [k for r in rules["rules"] for k in r["key_exprs"] if k.startswith("beyond/*")]
    assert by_id["describer-in-ingress"]["key_exprs"] == sorted(
        [
            "beyond/robot/language/words",
            "beyond/robot/language/words/@adv/**",
            "beyond/robot/progress/*",
            "beyond/robot/clock",  # a replay's stream clock, which every service may follow
            # everyone's ledger, kept by every service (runtime.resilience.ledger)
            "beyond/robot/ledger/*",
        ]
    )
    assert "beyond/robot/clock" in by_id["ingest-out-ingress"]["key_exprs"]  # the player's
    assert "beyond/robot/clock" not in describer_puts
    assert "beyond/robot/affordance/ask" in by_id["reasoner-serve-ingress"]["key_exprs"]
    tools = [r for r in rules["rules"] if r["id"].startswith("tools-")]
    assert tools and not any(
        {"put", "delete", "declare_queryable", "liveliness_token"} & set(r["messages"])
        for r in tools
        if r["flows"] == ["ingress"]
    )
    policies = {p["id"]: p for p in rules["policies"]}
    assert set(policies) == {*SERVICES, "tools", "robot", "workstation", "router"}
    # a side may do what its services may: the robot's router carries the robot's traffic
    robot_puts = set(by_id["robot-out-ingress"]["key_exprs"])
    assert robot_puts >= set(by_id["gestures-out-ingress"]["key_exprs"])
    assert not robot_puts & {"beyond/robot/language/description", "beyond/robot/language/words"}


def test_a_rule_naming_an_undeclared_key_is_an_error() -> None:
    decls = registry.declarations()
    with pytest.raises(InputError, match="unknown stream declared by service 'x'"):
        acl.Declaration("x", publishes=("sensors",))
    orphan = [d for d in decls if d.name != "describer"]  # now nobody publishes descriptions
    speech_only = [*orphan, acl.Declaration("listener", subscribes=("description",))]
    with pytest.raises(InputError, match="subscribes to 'description', which no service"):
        acl.access_control(speech_only, registry.SIDES)


class Undeclared(Service):
    name = "undeclared"
    subscribes = ("words",)
    publishes = ()
    serves = ()

    async def setup(self) -> None:
        self.subscribe(self.bus.keys.words, WordProbabilities, lambda m: None)
        self.publisher(self.bus.keys.description, Description)  # not declared


async def test_a_service_may_not_open_a_key_its_class_does_not_declare() -> None:
    bus = Bus.open(BusConfig(mode="peer", port=7893, listen=("tcp/127.0.0.1:0",)))
    try:
        with pytest.raises(InputError, match="may publish only on the keys its class declares"):
            await Undeclared(bus=bus).run(install_signals=False)
    finally:
        bus.close()
    for name in SERVICES:  # every registry service declares, so has a place in the rules
        assert acl.declaration_of(name, service_class(name)).name == name


def test_secure_config_is_tls_with_the_identity_and_no_peers(store: Path) -> None:
    config = load_config({"BEYOND_ZENOH_SECURE": str(store)})
    assert config.mode == "client" and config.endpoints() == ([], ["tls/127.0.0.1:7447"])
    zc = zenoh_config(config.with_(identity="describer"))
    tls = zc.get_json("transport/link/tls")
    assert "describer.crt" in tls and '"enable_mtls":true' in tls.replace(" ", "")
    with pytest.raises(InputError, match="links only over TLS"):
        zenoh_config(config.with_(connect=("tcp/127.0.0.1:7447",)))
    with pytest.raises(InputError, match="no peers"):
        load_config({"BEYOND_ZENOH_SECURE": str(store), "BEYOND_ZENOH_MODE": "peer"})


def _expire(store: Path, name: str) -> None:
    long_ago = dt.datetime.now(dt.UTC) - dt.timedelta(days=10)
    keystore.add(store, name, days=1, not_before=long_ago)


def _foreign(store: Path, other: Path, name: str) -> None:
    keystore.init(other, [name])
    for ext in ("crt", "key"):
        shutil.copy(other / f"{name}.{ext}", store / f"{name}.{ext}")


@pytest.mark.parametrize("problem", ["expired", "other CA", "missing"])
@pytest.mark.parametrize("command", ["up", "echo"])
def test_bad_certificate_is_one_line_exit_2(
    store: Path, tmp_path: Path, problem: str, command: str
) -> None:
    copy = tmp_path / "store"
    shutil.copytree(store, copy)
    name = "describer" if command == "up" else "tools"
    if problem == "expired":
        _expire(copy, name)
    elif problem == "other CA":
        _foreign(copy, tmp_path / "other", name)
    else:
        (copy / f"{name}.crt").unlink()
    argv = {
        "up": ["up", "--secure", str(copy), "--no-live", "--timeout", "30"],
        "echo": ["echo", "--secure", str(copy), "beyond/robot/language/description"],
    }[command]
    start = time.monotonic()
    result = beyond(*argv)
    took = time.monotonic() - start
    print(f"{command} with a {problem} certificate: exit {result.returncode} in {took:.2f} s")
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert f"{name}.crt" in lines[0]
    assert {"expired": "expired on", "other CA": "not signed by", "missing": "missing"}[
        problem
    ] in lines[0]
    assert result.stdout == ""


def test_secure_deploy_files_load_and_refuse_plain_endpoints(store: Path) -> None:
    secure = REPO / "deploy" / "zenoh-secure"
    env = {
        "BEYOND_ZENOH_SECURE": str(store),
        "BEYOND_ZENOH_CONFIG": str(secure / "client.json5"),
        "BEYOND_ZENOH_ROUTER": "tls/10.0.0.2:7447",
    }
    zc = zenoh_config(load_config(env).with_(identity="gestures"))
    assert "tls/10.0.0.2:7447" in zc.get_json("connect/endpoints")
    with pytest.raises(InputError, match="links only over TLS"):
        zenoh_config(load_config({**env, "BEYOND_ZENOH_ROUTER": "tcp/10.0.0.2:7447"}))
    router = load_config({**env, "BEYOND_ZENOH_CONFIG": str(secure / "router.json5")})
    with pytest.raises(InputError, match="needs the deployment's access rules"):
        zenoh_config(router.with_(mode="router"))
    zc = zenoh_config(router.with_(mode="router"), registry.access_rules(store))
    assert '"default_permission":"deny"' in zc.get_json("access_control").replace(" ", "")
    with pytest.raises(InputError, match="links only over TLS"):
        plain = load_config({**env, "BEYOND_ZENOH_CONFIG": str(REPO / "deploy/zenoh/router.json5")})
        zenoh_config(plain.with_(mode="router"))


def test_secure_compose_override_covers_every_service() -> None:
    yaml = pytest.importorskip("yaml")
    base = yaml.safe_load((REPO / "docker-compose.yml").read_text())["services"]
    override = yaml.safe_load((REPO / "docker-compose.secure.yml").read_text())["services"]
    assert set(override) == set(base) | {"robot-router"}
    assert "--secure" in override["router"]["command"]
    robot_router = override["robot-router"]
    assert robot_router["profiles"] == ["robot"] and "--secure" in robot_router["command"]
    local = robot_router["command"][robot_router["command"].index("--listen") + 1]
    for name in set(base) - {"router"}:
        env = override[name]["environment"]
        assert env["BEYOND_ZENOH_SECURE"] == "/etc/beyond/keys", name
        assert env["BEYOND_ZENOH_ROUTER"].startswith("tls/"), name
        assert any(v.endswith(":/etc/beyond/keys:ro") for v in override[name]["volumes"]), name
        if "robot" in base[name]["profiles"]:  # the robot's services use the robot's router
            assert env["BEYOND_ZENOH_ROUTER"] == local, name
