"""Per-service options from a config file, so one file can configure a whole deployment.

The file is YAML or JSON: `{"services": {"<service>": {"<option>": value, ...}, ...}}`. Options
are the keyword arguments of the service's constructor; an unknown service or option is an
InputError naming the valid ones, caught at start-up rather than half-way through a run.
"""

from __future__ import annotations

import inspect
import json
import math
import typing
from pathlib import Path
from typing import Any

import msgspec

from beyond_self.core.errors import InputError, unknown


def load_options(path: str | Path | None) -> dict[str, dict[str, Any]]:
    """The `services` section of a config file ({} without a file)."""
    if path is None:
        return {}
    p = Path(path)
    if not p.is_file():
        raise InputError(f"service config file {p} does not exist")
    try:
        text = p.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(
            f"service config {p} is not UTF-8 text; valid: a YAML or JSON file"
        ) from None
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
    """The options `cls.__init__` accepts (the fields of `cls.Options`, a class whose options
    are one value); anything else is an InputError listing the valid."""
    grouped = getattr(cls, "Options", None)
    if grouped is not None:
        valid = [f.name for f in msgspec.structs.fields(grouped)]
        hints = typing.get_type_hints(grouped)
    else:
        params = inspect.signature(cls).parameters
        valid = [n for n, p in params.items() if p.kind == p.KEYWORD_ONLY and n not in _BASE]
        hints = typing.get_type_hints(getattr(cls, "__init__"))  # noqa: B009 (mypy: class)
    for name in options:
        if name not in valid:
            raise unknown(f"option of service {service!r}", name, valid)
    return {name: _typed(service, name, value, hints.get(name)) for name, value in options.items()}


def _typed(service: str, name: str, value: Any, hint: Any) -> Any:
    """`value` as the constructor's annotation says, or an InputError naming the expected type.

    Why at start-up: a value of the wrong type (effects_wait_s="abc") is otherwise found only
    when the service first uses it, half-way through a run, and the gesture it was handling is
    then never described. Every numeric option is a size, a count, a rate, a scale or a wait, so
    numbers must also be finite and >= 0."""
    if hint is None:
        return value
    try:
        out = msgspec.convert(value, hint, strict=False)
    except msgspec.ValidationError:
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:77] + "..."
        raise InputError(
            f"option {name} of service {service!r} must be {_type_name(hint)}; got {shown}"
        ) from None
    number = isinstance(out, int | float) and not isinstance(out, bool)
    if number and not (math.isfinite(out) and out >= 0):
        raise InputError(
            f"option {name} of service {service!r} must be a finite number >= 0; got {out}"
        )
    return out


def _type_name(hint: Any) -> str:
    return str(hint).replace("typing.", "") if not isinstance(hint, type) else hint.__name__


_BASE = {"config", "bus", "clock", "health_period", "name"}
