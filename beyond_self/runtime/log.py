"""Structured logging: one JSON object per line on stderr (or plain text for people).

Why JSON lines: several services log into one terminal or one journal; a line that carries
`service`, `event` and the fields (key, reason, counts) can be filtered and counted by tools,
and is still readable. BEYOND_LOG_FORMAT=text switches to plain lines; BEYOND_LOG_LEVEL sets the
level (default INFO).
"""

from __future__ import annotations

import json
import logging
import os
import sys
import time
from typing import Any


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "t": round(record.created, 6),
            "level": record.levelname.lower(),
            "logger": record.name,
            "event": record.getMessage(),
        }
        fields = getattr(record, "fields", None)
        if isinstance(fields, dict):
            entry.update(fields)
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, default=str)


class TextFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        fields = getattr(record, "fields", None)
        extra = (
            " " + " ".join(f"{k}={v}" for k, v in fields.items())
            if isinstance(fields, dict)
            else ""
        )
        stamp = time.strftime("%H:%M:%S", time.localtime(record.created))
        text = f"{stamp} {record.levelname.lower():7s} {record.name}: {record.getMessage()}{extra}"
        if record.exc_info:
            text += "\n" + self.formatException(record.exc_info)
        return text


def setup_logging(level: str | None = None, fmt: str | None = None) -> None:
    """Configure the root logger once per process (idempotent)."""
    root = logging.getLogger()
    if getattr(root, "_beyond_configured", False):
        return
    handler = logging.StreamHandler(sys.stderr)
    fmt = fmt or os.environ.get("BEYOND_LOG_FORMAT", "json")
    handler.setFormatter(TextFormatter() if fmt == "text" else JsonFormatter())
    root.addHandler(handler)
    root.setLevel((level or os.environ.get("BEYOND_LOG_LEVEL", "INFO")).upper())
    root._beyond_configured = True  # type: ignore[attr-defined]


def event(logger: logging.Logger, level: int, name: str, **fields: Any) -> None:
    """Log `name` with structured fields."""
    logger.log(level, name, extra={"fields": fields})
