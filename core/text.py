"""How an error message quotes a client's input: at most :data:`QUOTE` characters of any
one value (a joint name, a token of a file), so a detail stays short whatever was sent.
Shared by the core's readers and the service's errors (``service.errors``)."""

from __future__ import annotations

QUOTE = 100  # characters of client input an error detail may quote


def clip(text: object, limit: int = QUOTE) -> str:
    """``text`` as a string of at most ``limit`` characters (``…`` marks a cut)."""
    s = str(text)
    return s if len(s) <= limit else s[: limit - 1] + "…"


def quoted(value: object) -> str:
    """``repr`` of ``value`` clipped to :data:`QUOTE` characters: how a message names
    what a client sent."""
    return repr(clip(value)) if isinstance(value, str) else clip(repr(value))
