"""The service's log: one JSON object per line, whoever writes it, each with its level
and time.

The service's own events are written as JSON already (the access log, ``models_ready``,
``slow-reader``); uvicorn's lines (start, stop, "Invalid HTTP request received.") and an
unexpected error's traceback were plain text among them, which a collector reading JSON
lines drops or splits (an ops audit). :class:`JSONLines` wraps anything that is not a
JSON object: ``{"time", "level", "event": "log", "logger", "message"[, "exception"]}``,
and gives the service's own objects the same two fields in front:
``{"time", "level", "event": ..., ...}``.

``level`` is the record's level in lower case (``debug``, ``info``, ``warning``,
``error``, ``critical``) on every line: the service's own events had none, so an alert on
``level=error`` missed ``models_not_ready`` (an ops audit). ``time`` is when the line was
logged, UTC, RFC 3339 with milliseconds (``2026-12-06T07:01:02.345Z``): no line had one,
which a runtime that adds its own (k8s, docker, journald) hides, but a plain
``pose-service 2>>file`` did not.
"""

from __future__ import annotations

import logging
import time
from typing import Any

import orjson

#: Fields every line starts with; an event of the service's own never sets them itself.
STAMPED = ("time", "level")


def stamp(created: float) -> str:
    """``created`` (seconds since the epoch) as UTC RFC 3339 with milliseconds."""
    ms = int(created * 1000)
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(ms // 1000)) + f".{ms % 1000:03d}Z"


def event_line(level: str, fields: dict[str, Any], created: float | None = None) -> str:
    """One line as :class:`JSONLines` writes it, for a line written without logging (a
    refused start's ``start_refused``, before logging is set up): ``fields`` after
    ``time`` (``created``, default now) and ``level``."""
    head = {"time": stamp(time.time() if created is None else created), "level": level}
    return orjson.dumps({**head, **fields}).decode()


class JSONLines(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        message = record.getMessage()
        head = {"time": stamp(record.created), "level": record.levelname.lower()}
        if record.exc_info is None and message.startswith("{") and message.endswith("}"):
            own = _own(message)
            if own is not None:  # written as JSON by the service: its fields after ours
                return orjson.dumps({**head, **own}).decode()
        line: dict[str, Any] = {**head, "event": "log", "logger": record.name,
                                "message": message}  # fmt: skip
        if record.exc_info is not None:
            line["exception"] = self.formatException(record.exc_info)
        elif record.stack_info:
            line["exception"] = self.formatStack(record.stack_info)
        return orjson.dumps(line).decode()


def _own(message: str) -> dict[str, Any] | None:
    """The service's own event in ``message`` (a JSON object), without the fields every
    line sets (``STAMPED``: kept under ``event_<name>`` if an event ever sets one); None
    for a message that only looks like one."""
    try:
        fields = orjson.loads(message)
    except orjson.JSONDecodeError:
        return None
    if not isinstance(fields, dict):
        return None
    for name in STAMPED:
        if name in fields:
            fields[f"event_{name}"] = fields.pop(name)
    return fields


#: uvicorn's line for bytes its parser refuses, one per refusal (a client looping garbage
#: for 3 s wrote 7,482 of them, an ops audit): dropped, as the protocol logs each refusal
#: itself, with its status, client and request id, a line a second at most
#: (``service.transport``: ``connection_closed``, ``malformed-http``).
PARSER_REFUSED = "Invalid HTTP request received."


class DropParserRefusals(logging.Filter):
    """Drops uvicorn's :data:`PARSER_REFUSED` lines (``service.transport`` logs them)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.msg != PARSER_REFUSED


def log_config(level: str) -> dict[str, Any]:
    """The ``logging.config.dictConfig`` of the service and of uvicorn (its loggers kept,
    their lines as JSON), at ``level``."""
    level = level.upper()
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"json": {"()": JSONLines}},
        "filters": {"parser_refusals": {"()": DropParserRefusals}},
        "handlers": {
            "stderr": {
                "class": "logging.StreamHandler",
                "formatter": "json",
                "stream": "ext://sys.stderr",
            }
        },
        "loggers": {
            name: {"handlers": ["stderr"], "level": level, "propagate": False, **more}
            for name, more in (
                ("uvicorn", {}),
                ("uvicorn.error", {"filters": ["parser_refusals"]}),
                ("uvicorn.access", {}),
            )
        },
        "root": {"handlers": ["stderr"], "level": level},
    }
