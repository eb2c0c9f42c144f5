"""docker-compose.yml, Dockerfile and deploy/: checked without a Docker engine.

`check_compose` reads the compose file as Docker Compose would (PyYAML, merge keys, `${VAR:-x}`
defaults) and reports every problem it finds: a service without image or build, a build context
or Dockerfile (or a file it copies) that is missing, a command the `beyond` CLI would refuse, a
config file a command or variable names that is not where the mounts put it (or does not load),
an undeclared network or volume, a service in the wrong profile or depending on one that is not
started with it, an unknown BEYOND_* variable, a router endpoint nobody serves, service options
the service does not have, a restart policy other than `beyond up`'s (on failure, a bounded
number of times). The mutation tests below show each check fails when it should.
"""

from __future__ import annotations

import contextlib
import copy
import io
import re
import shlex
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml

from beyond_self.cli import COMMANDS, build_parser
from beyond_self.runtime.bus.config import BLOCK_CLOSE_MS, ENV_VARS
from beyond_self.services.options import check_options, load_options
from beyond_self.services.registry import PROFILES, service_class

REPO = Path(__file__).resolve().parent.parent
COMPOSE = REPO / "docker-compose.yml"
KNOWN_ENV = set(ENV_VARS) | {"BEYOND_CLOCK", "BEYOND_LOG_FORMAT", "BEYOND_LOG_LEVEL", "BEYOND_DATA"}
PATH_OPTIONS = ("recording", "log", "models", "clusters", "model")  # options naming input files
WAIT_BEFORE_CLOSE = "transport/link/tx/queue/congestion_control/block/wait_before_close"
TOP_LEVEL = {"name", "services", "networks", "volumes", "configs", "secrets"}
SIDES = {"robot": set(PROFILES["robot"]), "workstation": set(PROFILES["workstation"])}


def expand(value: str) -> str:
    """`${VAR:-default}` / `${VAR-default}` -> default, `${VAR}` -> '' (nothing set here)."""
    return re.sub(
        r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::?-([^}]*))?\}", lambda m: m.group(2) or "", value
    )


class Checker:
    def __init__(self, data: Any, root: Path) -> None:
        self.data = data
        self.root = root
        self.problems: list[str] = []
        self._dockerfiles: dict[Path, dict[str, Any]] = {}

    def bad(self, where: str, text: str) -> None:
        self.problems.append(f"{where}: {text}")

    # -- whole file ------------------------------------------------------------------------

    def run(self) -> list[str]:
        data = self.data
        if not isinstance(data, dict) or not isinstance(data.get("services"), dict):
            self.bad("compose", "no 'services' mapping")
            return self.problems
        for key in data:
            if key not in TOP_LEVEL and not str(key).startswith("x-"):
                self.bad("compose", f"unknown top-level key {key!r}")
        self.services: dict[str, Any] = data["services"]
        self.networks = set((data.get("networks") or {}).keys())
        self.volumes = set((data.get("volumes") or {}).keys())
        for name, service in self.services.items():
            if not isinstance(service, dict):
                self.bad(name, "service is not a mapping")
                continue
            self.check_service(name, service)
        self.check_profiles()
        return self.problems

    # -- one service -----------------------------------------------------------------------

    def check_service(self, name: str, s: dict[str, Any]) -> None:
        self.check_restart(name, s)
        entrypoint = self.check_image(name, s)
        mounts = self.check_volumes(name, s)
        self.check_networks(name, s)
        env = self.environment(name, s)
        command = s.get("command")
        if command is None:
            self.bad(name, "no command (the image's default only prints help)")
            return
        argv = shlex.split(command) if isinstance(command, str) else [str(c) for c in command]
        argv = [expand(a) for a in argv]
        if s.get("entrypoint") is not None:
            ep = s["entrypoint"]
            entrypoint = shlex.split(ep) if isinstance(ep, str) else [str(e) for e in ep]
        if entrypoint is None:
            return  # reported already
        if entrypoint != ["beyond"]:
            self.bad(name, f"entrypoint {entrypoint} is not the beyond CLI")
            return
        args = self.parse(name, argv)
        if args is None:
            return
        for key in env:
            if key.startswith("BEYOND_") and key not in KNOWN_ENV:
                self.bad(name, f"unknown variable {key} (known: {', '.join(sorted(KNOWN_ENV))})")
        zenoh_file = getattr(args, "zenoh_config", None) or env.get("BEYOND_ZENOH_CONFIG")
        mode = None
        if zenoh_file:
            mode = self.check_zenoh_config(name, zenoh_file, mounts)
        if args.command == "router" and mode not in (None, "router"):
            self.bad(name, f"router runs with a {mode} config")
        if args.command == "service":
            config = getattr(args, "config", None)
            if config:
                self.check_service_options(name, args.name, config, mounts)
        routers = env.get("BEYOND_ZENOH_ROUTER", "")
        for endpoint in [e for e in routers.split(",") if e.strip()]:
            self.check_endpoint(name, s, endpoint.strip())

    def parse(self, name: str, argv: list[str]) -> Any:
        if not argv or argv[0] not in COMMANDS:
            self.bad(name, f"command {argv[:1]} is not a beyond command")
            return None
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                return build_parser(argv[0]).parse_args(argv)
        except SystemExit:
            last = err.getvalue().strip().splitlines()[-1:] or ["refused"]
            self.bad(name, f"beyond {' '.join(argv)}: {last[0]}")
            return None

    def check_restart(self, name: str, s: dict[str, Any]) -> None:
        """Restarted when it dies, as `beyond up` restarts its services: on failure only (a
        service that exits 0 meant to stop), with a bounded number of tries (the engine doubles
        its delay from 100 ms between them), never for ever."""
        policy = str(s.get("restart", "no"))
        kind, _, tries = policy.partition(":")
        if kind != "on-failure":
            self.bad(name, f"restart: {policy!r} (valid: on-failure:N, as beyond up restarts)")
        elif not tries.isdigit() or not 1 <= int(tries) <= 10:
            self.bad(name, f"restart: {policy!r} retries without bound (valid: on-failure:1..10)")

    def check_image(self, name: str, s: dict[str, Any]) -> list[str] | None:
        """The image's entrypoint (from the Dockerfile when built here); None if unknown."""
        build = s.get("build")
        if not s.get("image") and not build:
            self.bad(name, "neither image nor build")
            return None
        if not build:
            return ["beyond"] if str(s.get("image", "")).startswith("beyond-self") else []
        context = build if isinstance(build, str) else build.get("context", ".")
        dockerfile = (
            "Dockerfile" if isinstance(build, str) else build.get("dockerfile", "Dockerfile")
        )
        ctx = self.root / context
        if not ctx.is_dir():
            self.bad(name, f"build context {context} does not exist")
            return None
        path = ctx / dockerfile
        if not path.is_file():
            self.bad(name, f"Dockerfile {path.relative_to(self.root)} does not exist")
            return None
        return list(self.dockerfile(name, path, ctx)["entrypoint"])

    def dockerfile(self, name: str, path: Path, ctx: Path) -> dict[str, Any]:
        if path in self._dockerfiles:
            return self._dockerfiles[path]
        info: dict[str, Any] = {"entrypoint": [], "copies": {}}
        text = re.sub(r"\\\n", " ", path.read_text(encoding="utf-8"))
        if not re.search(r"^FROM\s+\S+", text, re.M):
            self.bad(name, f"{path.name} has no FROM")
        for line in text.splitlines():
            words = line.split()
            if not words or words[0].startswith("#"):
                continue
            if words[0] == "COPY":
                sources = [w for w in words[1:-1] if not w.startswith("--")]
                for src in sources:
                    for each in self.context_files(ctx, src):
                        if not (ctx / each).exists():
                            self.bad(name, f"{path.name} copies {each}, which does not exist")
                if len(sources) == 1:
                    info["copies"][words[-1].rstrip("/")] = ctx / sources[0]
            elif words[0] == "HEALTHCHECK" and "CMD" in words:
                check = yaml.safe_load(line.split("CMD", 1)[1].strip())
                if not isinstance(check, list) or check[:1] != ["beyond"]:
                    self.bad(name, f"{path.name} health check {check} is not a beyond command")
                else:
                    self.parse(name, [str(a) for a in check[1:]])
            elif words[0] == "ENTRYPOINT":
                info["entrypoint"] = yaml.safe_load(line.split(None, 1)[1])
        self._dockerfiles[path] = info
        return info

    @staticmethod
    def context_files(ctx: Path, src: str) -> list[str]:
        """What `COPY src` takes: the whole context is what .dockerignore lets in, when it
        excludes everything (`*`) and names each path allowed (`!path`)."""
        ignore = ctx / ".dockerignore"
        if src not in (".", "./") or not ignore.is_file():
            return [src]
        lines = [x.strip() for x in ignore.read_text(encoding="utf-8").splitlines()]
        lines = [x for x in lines if x and not x.startswith("#")]
        if lines[:1] != ["*"]:
            return [src]
        return [x[1:] for x in lines if x.startswith("!")]

    def check_volumes(self, name: str, s: dict[str, Any]) -> dict[str, Path]:
        """Container directory -> host path of every bind mount."""
        mounts: dict[str, Path] = {}
        for volume in s.get("volumes") or []:
            if not isinstance(volume, str):
                self.bad(name, f"volume {volume!r}: use the short SRC:DST[:MODE] syntax")
                continue
            parts = volume.split(":")
            if len(parts) < 2:
                self.bad(name, f"volume {volume!r} has no container path")
                continue
            src, dst = expand(parts[0]), parts[1]
            if src.startswith((".", "/")):
                host = (self.root / src).resolve()
                if not host.exists():
                    self.bad(name, f"bind mount source {src} does not exist")
                mounts[dst.rstrip("/")] = host
            elif src not in self.volumes:
                self.bad(name, f"named volume {src!r} is not declared under volumes")
        return mounts

    def check_networks(self, name: str, s: dict[str, Any]) -> None:
        nets = s.get("networks") or []
        names = list(nets.keys()) if isinstance(nets, dict) else list(nets)
        for net in names:
            if net not in self.networks:
                self.bad(name, f"network {net!r} is not declared under networks")
        mode = s.get("network_mode")
        if mode is not None:
            if names:
                self.bad(name, "network_mode and networks together")
            if mode.startswith("service:") and mode.split(":", 1)[1] not in self.services:
                self.bad(name, f"network_mode {mode}: no such service")
            elif mode not in ("host", "none", "bridge") and ":" not in mode:
                self.bad(name, f"unknown network_mode {mode!r}")
            if mode == "host" and s.get("ports"):
                self.bad(name, "ports are ignored with network_mode host")

    def environment(self, name: str, s: dict[str, Any]) -> dict[str, str]:
        env = s.get("environment") or {}
        if isinstance(env, list):
            env = dict(item.split("=", 1) if "=" in item else (item, "") for item in env)
        return {str(k): expand(str(v)) for k, v in env.items()}

    def host_path(self, name: str, path: str, mounts: dict[str, Path]) -> Path | None:
        """Where a container path comes from: a bind mount, else a COPY of the Dockerfile."""
        for table in (mounts, *[d["copies"] for d in self._dockerfiles.values()]):
            for dst, host in sorted(table.items(), key=lambda kv: -len(kv[0])):
                if path == dst or path.startswith(dst + "/"):
                    return host / path[len(dst) :].lstrip("/")
        self.bad(name, f"{path} is neither mounted nor in the image")
        return None

    def check_zenoh_config(self, name: str, path: str, mounts: dict[str, Path]) -> str | None:
        host = self.host_path(name, path, mounts)
        if host is None:
            return None
        if not host.is_file():
            self.bad(name, f"Zenoh config {path} ({host}) does not exist")
            return None
        import zenoh

        try:
            config = zenoh.Config.from_file(str(host))
        except Exception as exc:
            self.bad(name, f"Zenoh config {path} does not load: {exc}")
            return None
        mode = yaml.safe_load(config.get_json("mode"))
        return str(mode) if mode else "peer"

    def check_service_options(
        self, name: str, service: str, path: str, mounts: dict[str, Path]
    ) -> None:
        host = self.host_path(name, path, mounts)
        if host is None:
            return
        if not host.is_file():
            self.bad(name, f"service config {path} ({host}) does not exist")
            return
        try:
            options = load_options(host).get(service, {})
            check_options(service, service_class(service), options)
        except Exception as exc:
            self.bad(name, f"service config {path}: {exc}")
            return
        for key in PATH_OPTIONS:
            value = options.get(key)
            if isinstance(value, str):
                source = self.host_path(name, value, mounts)
                if source is not None and not source.exists():
                    self.bad(name, f"option {key}={value} ({source}) does not exist")

    def check_endpoint(self, name: str, s: dict[str, Any], endpoint: str) -> None:
        m = re.fullmatch(r"tcp/\[?([^\]]+?)\]?:(\d+)", endpoint)
        if m is None:
            self.bad(name, f"router endpoint {endpoint!r} is not tcp/HOST:PORT")
            return
        host, port = m.group(1), m.group(2)
        if host in ("127.0.0.1", "localhost", "::1"):
            if s.get("network_mode") != "host":
                return  # the container's own loopback: nothing in compose to check
            published = [
                other
                for other, o in self.services.items()
                if any(str(p).split(":")[0] == port for p in o.get("ports") or [])
            ]
            if not published:
                self.bad(name, f"{endpoint}: no service publishes port {port} on the host")
        elif host in self.services:
            target = self.services[host]
            ours = set(s.get("networks") or [])
            if not ours & set(target.get("networks") or []):
                self.bad(name, f"{endpoint}: shares no network with service {host!r}")
        elif not re.fullmatch(r"[0-9.]+|[A-Za-z0-9.-]+", host):
            self.bad(name, f"{endpoint}: bad host {host!r}")

    # -- profiles --------------------------------------------------------------------------

    def check_profiles(self) -> None:
        started: dict[str, set[str]] = {side: set() for side in SIDES}
        for name, s in self.services.items():
            if not isinstance(s, dict):
                continue
            profiles = s.get("profiles") or []
            if len(profiles) != 1 or profiles[0] not in SIDES:
                self.bad(name, f"profiles {profiles}; valid: exactly one of {sorted(SIDES)}")
                continue
            command = s.get("command") or []
            argv = shlex.split(command) if isinstance(command, str) else [str(c) for c in command]
            if argv[:1] == ["service"] and len(argv) > 1:
                started[profiles[0]].add(argv[1])
            deps = s.get("depends_on") or []
            for dep in deps.keys() if isinstance(deps, dict) else deps:
                if dep not in self.services:
                    self.bad(name, f"depends on {dep!r}, which is not a service")
                elif profiles[0] not in (self.services[dep].get("profiles") or []):
                    self.bad(name, f"depends on {dep!r}, which is not in profile {profiles[0]}")
        for side, wanted in SIDES.items():
            if started[side] != wanted:
                self.bad(
                    f"profile {side}",
                    f"starts services {sorted(started[side])}; the {side} side is {sorted(wanted)}",
                )
        if not any(
            (s.get("command") or [None])[0] == "router" and "workstation" in s.get("profiles", [])
            for s in self.services.values()
            if isinstance(s, dict)
        ):
            self.bad("profile workstation", "has no router")


def load_compose(path: Path = COMPOSE) -> Any:
    return yaml.safe_load(path.read_text(encoding="utf-8"))


def check_compose(data: Any, root: Path = REPO) -> list[str]:
    return Checker(data, root).run()


# -- the real file ---------------------------------------------------------------------------


def test_the_compose_file_has_no_problems() -> None:
    assert check_compose(load_compose()) == []


def test_profiles_split_the_pipeline_as_the_issue_says() -> None:
    services = load_compose()["services"]
    by_profile: dict[str, set[str]] = {}
    for name, s in services.items():
        for profile in s["profiles"]:
            by_profile.setdefault(profile, set()).add(name)
    assert by_profile == {
        "robot": {"ingest", "gestures", "objects"},
        "workstation": {"router", "reasoner", "describer", "speech"},
    }
    images = {s["image"] for s in services.values()}
    assert images == {"beyond-self:latest"}  # one image for everything
    assert all(s["build"]["dockerfile"] == "Dockerfile" for s in services.values())


def test_deploy_configs_load_and_agree() -> None:
    import zenoh

    configs = {
        p.stem: zenoh.Config.from_file(str(p)) for p in sorted((REPO / "deploy/zenoh").glob("*"))
    }
    assert set(configs) == {"router", "robot", "workstation"}
    modes = {k: yaml.safe_load(c.get_json("mode")) for k, c in configs.items()}
    assert modes == {"router": "router", "robot": "peer", "workstation": "client"}
    leases = {k: int(c.get_json("transport/link/tx/lease")) for k, c in configs.items()}
    assert len(set(leases.values())) == 1 and leases["router"] < 10_000  # faster than default
    # a blocking message gives up on a full queue before the lease runs out (runtime/bus/config.py)
    for path in sorted(REPO.glob("deploy/zenoh*/*.json5")):
        config = zenoh.Config.from_file(str(path))
        block_close_us = int(config.get_json(WAIT_BEFORE_CLOSE))
        assert block_close_us == BLOCK_CLOSE_MS * 1000, path
        assert block_close_us < int(config.get_json("transport/link/tx/lease")) * 1000, path
    assert all(yaml.safe_load(c.get_json("timestamping/enabled")) for c in configs.values())
    assert yaml.safe_load(configs["router"].get_json("listen/endpoints")) == ["tcp/[::]:7447"]
    options = load_options(REPO / "deploy/services.yaml")
    for name, opts in options.items():
        check_options(name, service_class(name), opts)


# -- it fails when it should ------------------------------------------------------------------


def mutated(change: Any) -> list[str]:
    data = copy.deepcopy(load_compose())
    change(data)
    return check_compose(data)


def _set(path: str, value: Any) -> Any:
    def change(data: Any) -> None:
        *parents, last = path.split(".")
        node = data
        for p in parents:
            node = node[p]
        if value is _DELETE:
            del node[last]
        else:
            node[last] = value

    return change


_DELETE = object()
ROBOT_JSON5 = "/etc/beyond/zenoh/robot.json5"
NO_YAML = "/etc/beyond/no.yaml"


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (_set("services.gestures.image", _DELETE), None),  # build alone is fine
        (
            lambda d: [d["services"]["gestures"].pop(k) for k in ("image", "build")],
            "gestures: neither image nor build",
        ),
        (_set("services.describer.build", {"context": ".", "dockerfile": "Nope"}), "Nope"),
        (_set("services.router.build", {"context": "no-such-dir"}), "build context no-such-dir"),
        (_set("services.reasoner.command", ["service", "reasonr"]), "reasoner: beyond service"),
        (_set("services.speech.command", ["speak"]), "is not a beyond command"),
        (_set("services.router.command", ["router", "--frobnicate"]), "unrecognized arguments"),
        (
            _set("services.objects.environment.BEYOND_ZENOH_CONFIG", "/etc/beyond/zenoh/x.json5"),
            "objects: Zenoh config /etc/beyond/zenoh/x.json5",
        ),
        (
            _set("services.router.command", ["router", "--zenoh-config", "/opt/elsewhere.json5"]),
            "/opt/elsewhere.json5 is neither mounted nor in the image",
        ),
        (
            _set(
                "services.router.command",
                ["router", "--zenoh-config", "/etc/beyond/zenoh/robot.json5"],
            ),
            "router runs with a peer config",
        ),
        (
            _set(
                "services.ingest.command", ["service", "ingest", "--config", "/etc/beyond/no.yaml"]
            ),
            "service config /etc/beyond/no.yaml",
        ),
        (_set("services.reasoner.networks", ["backbone"]), "network 'backbone' is not declared"),
        (_set("networks", {}), "network 'beyond' is not declared"),
        (_set("services.gestures.network_mode", "hostt"), "unknown network_mode"),
        (_set("services.reasoner.network_mode", "host"), "network_mode and networks together"),
        (_set("services.router.ports", _DELETE), "no service publishes port 7447"),
        (_set("services.speech.volumes", ["speech-out:/data/speech"]), "'speech-out' is not"),
        (_set("services.ingest.volumes", ["./no-such-dir:/recordings:ro"]), "./no-such-dir"),
        (_set("services.gestures.profiles", ["workstation"]), "profile robot"),
        (_set("services.objects.profiles", ["robot", "workstation"]), "objects: profiles"),
        (_set("services.describer.depends_on", ["routr"]), "depends on 'routr'"),
        (_set("services.reasoner.depends_on", ["gestures"]), "not in profile workstation"),
        (_set("services.router", _DELETE), "has no router"),
        (_set("services.objects", _DELETE), "profile robot: starts services"),
        (_set("services.reasoner.environment.BEYOND_ZENOH_ROUTR", "x"), "BEYOND_ZENOH_ROUTR"),
        (
            _set("services.describer.environment.BEYOND_ZENOH_ROUTER", "tcp/ruter:7447"),
            None,  # a host name outside compose (another machine) is allowed
        ),
        (
            _set("services.describer.environment.BEYOND_ZENOH_ROUTER", "udp//router"),
            "is not tcp/HOST:PORT",
        ),
        (_set("volumes", {}), "'speech' is not declared"),
        (_set("services.gestures.command", None), "gestures: no command"),
        (_set("extras", {}), "unknown top-level key 'extras'"),
        (
            _set("services.reasoner.restart", "unless-stopped"),
            "reasoner: restart: 'unless-stopped'",
        ),
        (_set("services.speech.restart", "on-failure"), "speech: restart: 'on-failure' retries"),
        (_set("services.ingest.restart", _DELETE), "ingest: restart: 'no'"),
    ],
)
def test_the_checker_reports_each_kind_of_problem(change: Any, expected: str | None) -> None:
    problems = mutated(change)
    if expected is None:
        assert problems == []
    else:
        assert any(expected in p for p in problems), problems


LAYERS = ("beyond_self", "core", "cognition", "runtime", "schemas", "services")


def test_the_checker_reads_the_files_on_disk(tmp_path: Path) -> None:
    """A copy of the tree with one config and one recording removed: both are reported."""
    for name in (*LAYERS, "recordings"):
        (tmp_path / name).symlink_to(REPO / name)
    for name in ("pyproject.toml", "README.md", "Dockerfile", ".dockerignore"):
        shutil.copy(REPO / name, tmp_path / name)
    shutil.copytree(REPO / "deploy", tmp_path / "deploy")
    assert check_compose(load_compose(), tmp_path) == []
    (tmp_path / "deploy/zenoh/workstation.json5").unlink()
    options = yaml.safe_load((tmp_path / "deploy/services.yaml").read_text())
    options["services"]["ingest"]["recording"] = "/recordings/missing.mcap"
    options["services"]["describer"]["nbest_sentences"] = 3
    (tmp_path / "deploy/services.yaml").write_text(yaml.safe_dump(options))
    (tmp_path / "README.md").unlink()
    problems = check_compose(load_compose(), tmp_path)
    for service in ("reasoner", "describer", "speech"):
        assert any(p.startswith(f"{service}: Zenoh config") for p in problems), problems
    assert any("ingest: option recording=/recordings/missing.mcap" in p for p in problems)
    assert any("describer: service config" in p and "nbest_sentences" in p for p in problems)
    assert any("copies README.md, which does not exist" in p for p in problems)


def test_the_checker_reads_the_dockerfile(tmp_path: Path) -> None:
    """A health check the CLI refuses, and a context file .dockerignore lets in that is gone."""
    for name in (*LAYERS, "recordings", "deploy"):
        (tmp_path / name).symlink_to(REPO / name)
    for name in ("pyproject.toml", "README.md", ".dockerignore"):
        shutil.copy(REPO / name, tmp_path / name)
    text = (REPO / "Dockerfile").read_text(encoding="utf-8")
    assert '"beyond", "health"' in text
    (tmp_path / "Dockerfile").write_text(text.replace('"beyond", "health"', '"beyond", "helth"'))
    (tmp_path / "beyond_self").unlink()
    problems = check_compose(load_compose(), tmp_path)
    assert any("command ['helth'] is not a beyond command" in p for p in problems), problems
    assert any("copies beyond_self, which does not exist" in p for p in problems), problems
