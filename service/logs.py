"""The service's log: one JSON object per line, whoever writes it.

The service's own events are written as JSON already (the access log, ``models_ready``,
``slow-reader``); uvicorn's lines (start, stop, "Invalid HTTP request received.") and an
unexpected error's traceback were plain text among them, which a collector reading JSON
lines drops or splits (an ops audit). :class:`JSONLines` passes a JSON object through and
wraps anything else: ``{"event": "log", "logger", "level", "message"[, "exception"]}``.
"""

from __future__ import annotations

import logging
from typing import Any

import orjson


class JSONLines(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        message = record.getMessage()
        if record.exc_info is None and message.startswith("{") and message.endswith("}"):
            return message  # written as JSON by the service
        line: dict[str, Any] = {
            "event": "log",
            "logger": record.name,
            "level": record.levelname.lower(),
            "message": message,
        }
        if record.exc_info is not None:
            line["exception"] = self.formatException(record.exc_info)
        return orjson.dumps(line).decode()


def log_config(level: str) -> dict[str, Any]:
    """The ``logging.config.dictConfig`` of the service and of uvicorn (its loggers kept,
    their lines as JSON), at ``level``."""
    level = level.upper()
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "formatters": {"json": {"()": JSONLines}},
        "handlers": {
            "stderr": {
                "class": "logging.StreamHandler",
                "formatter": "json",
                "stream": "ext://sys.stderr",
            }
        },
        "loggers": {
            name: {"handlers": ["stderr"], "level": level, "propagate": False}
            for name in ("uvicorn", "uvicorn.error", "uvicorn.access")
        },
        "root": {"handlers": ["stderr"], "level": level},
    }
