"""Per-service options from a config file, so one file can configure a whole deployment.

The file is YAML or JSON: `{"services": {"<service>": {"<option>": value, ...}, ...}}`. Options
are the keyword arguments of the service's constructor; an unknown service or option is an
InputError naming the valid ones, caught at start-up rather than half-way through a run.
"""

from __future__ import annotations

import inspect
import json
from pathlib import Path
from typing import Any

from cognition.errors import InputError, unknown


def load_options(path: str | Path | None) -> dict[str, dict[str, Any]]:
    """The `services` section of a config file ({} without a file)."""
    if path is None:
        return {}
    p = Path(path)
    if not p.is_file():
        raise InputError(f"service config file {p} does not exist")
    text = p.read_text(encoding="utf-8")
    try:
        if p.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml

            data = yaml.safe_load(text)
    except Exception as exc:
        raise InputError(
            f"service config {p} is not valid {p.suffix[1:] or 'YAML'}: {exc}"
        ) from None
    if data is None:
        return {}
    if not isinstance(data, dict) or not isinstance(data.get("services", {}), dict):
        raise InputError(f"service config {p}: expected a mapping with a 'services' mapping")
    services = data.get("services", {}) or {}
    for name, options in services.items():
        if not isinstance(options, dict):
            raise InputError(f"service config {p}: options of {name!r} must be a mapping")
    return services


def check_options(service: str, cls: type, options: dict[str, Any]) -> dict[str, Any]:
    """The options `cls.__init__` accepts; anything else is an InputError listing the valid."""
    params = inspect.signature(cls).parameters
    valid = [n for n, p in params.items() if p.kind == p.KEYWORD_ONLY and n not in _BASE]
    for name in options:
        if name not in valid:
            raise unknown(f"option of service {service!r}", name, valid)
    return options


_BASE = {"config", "bus", "clock", "health_period", "name"}
