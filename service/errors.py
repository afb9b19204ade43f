"""Domain errors and their one mapping to HTTP problem details (RFC 9457).

Everything a client can get wrong or run into is a ``PoseError`` (or, for the body
reader, ``BodyError``); ``install_handlers`` turns those, FastAPI's request validation
errors and anything unexpected into ``application/problem+json``. Details quote at most
``QUOTE`` characters of any one value of the client's input (``core.text.quoted``; an
object, a list or a literal as JSON writes it, ``{"x": [null, true]}``, by
``core.text.shown``, the one writer every detail quotes such a value with), and are at
most ``MAX_DETAIL`` characters.
"""

from __future__ import annotations

import contextlib
import logging
import re
from collections.abc import Sequence
from http import HTTPStatus
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from core.skeleton import JOINT_NAMES
from core.text import QUOTE, clip, did_you_mean, near_name, printable, quoted, shown

PROBLEM_JSON = "application/problem+json"
PROBLEM_BASE = "https://marionette.dev/problems/"
REASON = "pose.reason"  # scope key: why a request was refused (a problem type), for metrics
#: scope key: the setting whose limit refused a request (a 413's, a 429's), for the access log
LIMIT = "pose.limit"
#: scope key: perf_counter() when the request arrived (its head read: the HTTP protocol,
#: ``service.transport``; else when the app first saw it); its deadline counts from it
T0 = "pose.t0"
MAX_DETAIL = 4000  # characters of any detail, whatever built it
MAX_ERRORS = 20  # field errors a problem lists
#: a character's numbers, in its own units (``service.characters.MAX_COORDINATE``): one
#: past it is named with its value (:func:`_message`)
CHARACTER_BOUND = 1.0e7
log = logging.getLogger("service")


class PoseError(Exception):
    """Base of every error a client can cause; carries the HTTP status and a title."""

    status = 422
    title = "Invalid request body"  # the title of every invalid-request problem
    type_ = "invalid-request"
    retry_after: int | None = None
    headers: dict[str, str] | None = None  # an answer's own headers (a 416's Content-Range)
    #: the setting whose limit this refusal enforces (``POSE_MAX_BODY_BYTES``), if any: the
    #: access log's ``limit`` (a 413 or 429 did not say which limit it was)
    limit: str | None = None

    def __init__(self, detail: str, **extra: Any) -> None:
        super().__init__(detail)
        self.detail = detail
        if extra.get("limit") is not None:  # (a setting's name: never a field of the problem)
            self.limit = str(extra.pop("limit"))
        self.extra = extra


def refused(scope: Any, exc: PoseError) -> None:
    """Note in ``scope`` why the request was refused: ``exc``'s problem type (the metrics'
    reason, the access log's ``outcome``) and the limit it enforces, if any."""
    scope[REASON] = exc.type_
    if exc.limit is not None:
        scope[LIMIT] = exc.limit


class InvalidRequest(PoseError):
    """Duplicate target, pin on a target, degenerate pose, missing base points…"""


class MalformedBody(PoseError):
    status = 400
    title = "Malformed request body"
    type_ = "malformed-body"


class MalformedHTTP(PoseError):
    """Bytes the server's HTTP parser cannot read as a request (answered below the app, by
    the protocol: :mod:`service.transport`, with :func:`raw_answer`)."""

    status = 400
    title = "Malformed HTTP request"
    type_ = "malformed-http"


class HeadTooLarge(PoseError):
    """A request line and headers longer than the server reads (:mod:`service.transport`)."""

    status = 431
    title = "Request header fields too large"
    type_ = "head-too-large"


class HeadTimeout(PoseError):
    """A request line and headers not whole within the head timeout, from their first byte
    (a slowloris: :mod:`service.transport`)."""

    status = 408
    title = "Request head timeout"
    type_ = "head-timeout"


class TooManyConnections(PoseError):
    """A connection past the worker's bound on open ones (:mod:`service.transport`)."""

    status = 503
    title = "Too many connections"
    type_ = "too-many-connections"
    retry_after = 1


class RequestTimeout(PoseError):
    """The body did not arrive within the deadline (a stalled or too slow upload)."""

    status = 408
    title = "Request body timeout"
    type_ = "request-timeout"


class MalformedRange(PoseError):
    """A ``Range`` header on a static file that cannot be read as byte ranges
    (:mod:`service.files`)."""

    status = 400
    title = "Malformed Range header"
    type_ = "malformed-range"


class RangeNotSatisfiable(PoseError):
    """A ``Range`` of a static file that starts past its end (:mod:`service.files`); the
    answer's ``Content-Range: bytes */<size>`` gives the file's size (RFC 9110 15.5.17)."""

    status = 416
    title = "Range not satisfiable"
    type_ = "range-not-satisfiable"

    def __init__(self, detail: str, size: int) -> None:
        super().__init__(detail)
        self.headers = {"Content-Range": f"bytes */{size}"}


class TooManyItems(PoseError):
    status = 413
    title = "Too many items"
    type_ = "too-many-items"
    limit = "POSE_MAX_BATCH_ITEMS"


def too_many_items(field: str, count: int, limit: int, noun: str = "items") -> TooManyItems:
    """The 413 of a batch whose ``field`` holds ``count`` ``noun`` past ``limit``
    (``POSE_MAX_BATCH_ITEMS``): one wording for the item list, the columnar form and a
    clip's edits, naming the setting and what to send instead, as a body too large does
    (they said the counts alone, the field on one route only: an API audit, 2026-12-07)."""
    return TooManyItems(
        f"{field}: {count} {noun} exceed the limit of {limit} per batch (the server's "
        f"{TooManyItems.limit}): send them in several requests of at most {limit}"
    )


class PayloadTooLarge(PoseError):
    status = 413
    title = "Request body too large"
    type_ = "payload-too-large"
    limit = "POSE_MAX_BODY_BYTES"


class UnsupportedMediaType(PoseError):
    status = 415
    title = "Unsupported media type"
    type_ = "unsupported-media-type"


class Unauthorized(PoseError):
    status = 401
    title = "Missing or wrong API key"
    type_ = "unauthorized"


class CorsRejected(PoseError):
    """A CORS preflight from an origin, method or header not allowed (Starlette's 400)."""

    status = 400
    title = "CORS preflight rejected"
    type_ = "cors-rejected"


class TooManyRequests(PoseError):
    status = 429
    title = "Too many concurrent requests"
    type_ = "too-many-requests"
    retry_after = 1


class NotReady(PoseError):
    status = 503
    title = "Models not ready"
    type_ = "not-ready"
    retry_after: int | None = 5


class ModelsFailed(NotReady):
    """The models failed to load, verify or warm up: the service does not retry, so no
    ``Retry-After`` (a client told to retry in 5 s did so for good: an ops audit); an
    operator fixes the models and restarts the process. The same 503, its own type."""

    title = "Models failed to load"
    type_ = "models-failed"
    retry_after = None


class ShuttingDown(PoseError):
    status = 503
    title = "Shutting down"
    type_ = "shutting-down"
    retry_after = 1


class DeadlineExceeded(PoseError):
    status = 504
    title = "Deadline exceeded"
    type_ = "deadline-exceeded"
    retry_after: int | None = 1  # (none where the request's own work took the time)


class ClientDisconnected(PoseError):
    """The client went away: work stopped; logged as 499, never sent."""

    status = 499
    title = "Client closed request"
    type_ = "client-disconnected"


class BodyError(HTTPException):
    """A ``PoseError`` raised while FastAPI reads the body (which lets only
    ``HTTPException`` through), carried to the same problem mapping."""

    def __init__(self, error: PoseError) -> None:
        super().__init__(error.status, error.detail)
        self.error = error


class BodyInvalid(HTTPException):
    """Field errors found while validating the body off the event loop."""

    def __init__(self, errors: Sequence[Any], total: int = 0, partial: bool = False) -> None:
        super().__init__(422, "invalid request body")
        self.errors = list(errors)
        self.total = max(total, len(self.errors))  # errors found, listed or not
        self.partial = partial  # the look stopped early: more may follow
        self._answer: JSONResponse | None = None

    def answer(self) -> JSONResponse:
        """Its 422 (:func:`validation_problem`), worded once; the errors, which may quote
        much of the body (an input that is a list of a million numbers), are let go then."""
        if self._answer is None:
            self._answer = validation_problem(self.errors, self.total, self.partial)
            self.errors = []
        return self._answer


#: The schemes a 401 names (the gate takes X-API-Key or Authorization: Bearer).
WWW_AUTHENTICATE = "ApiKey, Bearer"


def problem(
    status: int,
    title: str,
    detail: str,
    *,
    type_: str = "about:blank",
    headers: dict[str, str] | None = None,
    **extra: Any,
) -> JSONResponse:
    body: dict[str, Any] = {
        "type": type_ if type_ == "about:blank" else PROBLEM_BASE + type_,
        "title": title,
        "status": status,
        "detail": detail,
    }
    body.update(extra)
    body = _printable(body)  # a client's lone surrogate quoted anywhere: its escape
    if status == 401:
        headers = {**(headers or {}), "WWW-Authenticate": WWW_AUTHENTICATE}
    return JSONResponse(body, status_code=status, media_type=PROBLEM_JSON, headers=headers)


def _printable(value: Any) -> Any:
    if isinstance(value, str):
        return printable(value)
    if isinstance(value, dict):
        return {printable(str(k)): _printable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_printable(v) for v in value]
    return value


def raw_answer(exc: PoseError, extra: Sequence[tuple[bytes, bytes]] = ()) -> bytes:
    """``exc``'s answer as the bytes of a whole HTTP/1.1 response that closes the
    connection, for the protocol layer, which answers before any app runs: the body and
    headers of :func:`error_response`, then ``extra`` headers."""
    resp = error_response(exc)
    head = [f"HTTP/1.1 {resp.status_code} {HTTPStatus(resp.status_code).phrase}".encode()]
    head += [k.encode("latin-1") + b": " + v.encode("latin-1") for k, v in resp.headers.items()]
    head += [k + b": " + v for k, v in extra] + [b"connection: close", b"", b""]
    return b"\r\n".join(head) + bytes(resp.body)


#: A field's place as the messages write it (``items[2].targets[0].joint``, ``bvh``):
#: lower-case names (``spine2``) and indices only, so a client's own name in a detail
#: (``Bip01 L Forearm``, ``L: Forearm``) is never taken for one (an error on a field named
#: by the client's name says its location itself: ``core.characters.CharacterError``).
_LOCATION = re.compile(r"[a-z_][a-z0-9_]*(\[\d+\])*(\.[a-z_][a-z0-9_]*(\[\d+\])*)*")


def _field_error(detail: str) -> dict[str, str]:
    """An ``invalid-request`` detail (``targets[1]: duplicate target …``) as a field error:
    its location, its message; ``body`` where it names no field."""
    where, sep, message = detail.partition(": ")
    if not (sep and _LOCATION.fullmatch(where)):
        where, message = "body", detail
    return {"location": where, "message": message}


def every_item(found: Sequence[InvalidRequest], total: int = 0) -> InvalidRequest:
    """One 422 of the cross-field errors of many items (a batch's): each item's, the first
    ``MAX_ERRORS`` listed, as field errors are (a batch client fixed one item a round trip
    when only the first was told: an API audit, 2026-12-06); ``total``: how many were
    found, where only the first are in ``found``."""
    total = max(total, len(found))
    if total == 1:
        return found[0]
    errors = [field_error(e) for e in found[:MAX_ERRORS]]
    detail = "; ".join(e.detail for e in found[:3])
    if total > 3:
        detail += f"; and {total - 3} more"
    return InvalidRequest(detail, errors=errors)


def field_error(exc: PoseError) -> dict[str, str]:
    """``exc``'s one field error: its own where it says it (a location holding a client's
    joint name, ``service.characters``), else read from its detail."""
    own = exc.extra.get("errors")
    return dict(own[0]) if isinstance(own, list) and len(own) == 1 else _field_error(exc.detail)


def error_response(exc: PoseError) -> JSONResponse:
    """The one problem+json answer of a domain error (with ``Retry-After`` when useful).
    An ``invalid-request`` one has the shape of a field error's: its ``errors`` list names
    the field (``targets[1]: duplicate target …`` -> location ``targets[1]``)."""
    headers = dict(exc.headers or {})
    if exc.retry_after is not None:
        headers["Retry-After"] = str(exc.retry_after)
    detail = clip(exc.detail, MAX_DETAIL)
    extra = dict(exc.extra)
    if exc.type_ == "invalid-request" and "errors" not in extra:
        extra["errors"] = [_field_error(detail)]
    return problem(exc.status, exc.title, detail, type_=exc.type_, headers=headers or None, **extra)


def _location(loc: Sequence[Any]) -> str:
    """``items[2].targets[0].joint``: the same notation as the cross-field checks."""
    out = ""
    for part in loc:
        if (part == "body" and not out) or part == "[key]":
            continue
        out += f"[{part}]" if isinstance(part, int) else f"{'.' if out else ''}{clip(part, 40)}"
    return clip(out or "body", QUOTE)


def _near(value: Any, names: Sequence[str] = JOINT_NAMES) -> str:
    """`` (did you mean 'left_wrist'?)`` for a joint name near a canonical one (another
    case, a dash for the underscore, a letter off), else nothing."""
    if not isinstance(value, str) or len(value) > 40:
        return ""
    return did_you_mean(value, names)


#: a BVH body with nothing in it (``bvh: ""``, or blanks alone): what a 0-byte file sends
EMPTY_BVH = "the file is empty ({size}): send a BVH file's text, HIERARCHY first"


def _not_a_name(error: Any) -> str:
    """A joint's name given as no string: what was given, and for a pin given as an
    object, what a pin and a target are."""
    value = error.get("input")
    kinds = {dict: "an object", list: "a list", bool: "true or false", type(None): "null"}
    got = f"{kinds.get(type(value), 'a number')} ({quoted(value)})"  # (deep lists cut)
    held = isinstance(value, dict) and "pins" in error.get("loc", ())
    hint = (
        '; a pin holds a joint where it is: a joint to move is a target, {"joint": ..., '
        '"position": [x, y, z]}' if held else ""
    )  # fmt: skip
    return f"a joint's name (a string) is needed, not {got}{hint}"


def _not_canonical(name: str) -> str:
    """A key of the pose form's ``pose`` that is no canonical joint (a rig's own name,
    ``Head``, ``LeftHand``): what the form takes, and where a rig of one's own goes."""
    return (
        f"unknown joint {quoted(name)}{_near(name)}: the pose form takes the 21 canonical "
        f"joints ({', '.join(JOINT_NAMES)}); a skeleton of your own, with its own joint "
        "names, is sent in the character form (`character`, docs/characters.md)"
    )


def _message(error: Any) -> str:
    """pydantic's message, made specific where it is vague and never echoing much input."""
    kind = error.get("type", "")
    ctx = error.get("ctx") or {}
    value = error.get("input")
    if kind == "literal_error" and "'spine1'" in str(ctx.get("expected", "")):
        if not isinstance(value, str):  # no name at all (was: "unknown joint 1")
            return f"{_not_a_name(error)}; joints are {', '.join(JOINT_NAMES)}"
        if "[key]" in error.get("loc", ()):  # a bone, named by its child joint
            bones = JOINT_NAMES[1:]  # (the root ends none)
            root = " (the root: no bone ends at it)" if value == JOINT_NAMES[0] else ""
            near = "" if root else _near(value, bones)
            return f"no bone ends at {quoted(value)}{root}{near}; bones end at {', '.join(bones)}"
        return f"unknown joint {quoted(value)}{_near(value)}; joints are {', '.join(JOINT_NAMES)}"
    loc = tuple(error.get("loc", ()))
    if kind == "extra_forbidden" and loc[-2:-1] == ("pose",) and isinstance(loc[-1], str):
        return _not_canonical(loc[-1])  # (was "Extra inputs are not permitted")
    if kind == "extra_forbidden" and isinstance(ctx.get("meant"), str):  # service.field_names
        return f"Extra inputs are not permitted (did you mean {ctx['meant']!r}?)"
    if kind == "string_type" and ("pins" in loc[-2:] or loc[-1:] == ("joint",)):
        return _not_a_name(error)  # a character's joint (was "Input should be a valid string")
    if kind == "string_unicode" and isinstance(value, str):  # a lone surrogate's escape
        known = ctx.get("key")  # service.bounded.keyed: a key, a value, or not known
        what = "key or string" if known is None else "key" if known else "string"
        return (
            f"the {what} {quoted(value)} holds a lone surrogate (a \\ud800-\\udfff escape "
            "not in a pair), which no UTF-8 encodes"
        )
    if kind == "string_too_short" and tuple(error.get("loc", ()))[-1:] == ("bvh",):
        return EMPTY_BVH.format(size="0 bytes")
    if kind in ("model_type", "dict_type"):  # (was "a valid dictionary or instance of Pose")
        return f"a JSON object is required, not {_came(value)}"
    if kind == "list_type" and "input" in error:  # (was "Input should be a valid list")
        return f"a JSON array is required, not {_came(value)}"
    if kind == "finite_number":
        return NOT_FINITE
    if kind == "float_type" and type(value) is int:  # JSON allows any integer; a float not
        return f"{quoted(value)} is beyond any number this API takes (±1.8e308)"
    if kind in _SCALARS and "input" in error:  # (was "Input should be a valid number")
        return f"{_SCALARS[kind]} is required, not {_came(value)}"
    if (
        kind in ("less_than_equal", "greater_than_equal")
        and abs(float(ctx.get("le", ctx.get("ge", 0)))) == 1.0e4
    ):
        return f"coordinate {clip(value, 30)} beyond ±10000 m"
    if (
        kind in ("less_than_equal", "greater_than_equal")
        and abs(float(ctx.get("le", ctx.get("ge", 0)))) == CHARACTER_BOUND
        and isinstance(value, int | float)
    ):  # (was pydantic's, no value)
        return (
            f"{clip(value, 30)} is beyond ±{CHARACTER_BOUND:g}: a character's numbers are within "
            f"±{CHARACTER_BOUND:g} in its own units"
        )
    message = clip(error.get("msg", "invalid"), 2 * QUOTE)
    if kind in _BOUNDS and isinstance(value, int | float) and not isinstance(value, bool):
        return f"{message}, got {shown(value)}"  # (was pydantic's alone: the value not said)
    if kind in ("literal_error", "enum") and "input" in error:
        return f"{message}, got {clip(shown(value))}"
    return message


#: A number that is not finite (a float past the range reads as infinite: ``1e309``, which the
#: client never wrote as an infinity, was told "NaN and infinities are not"; an API audit,
#: 2026-12-08).
NOT_FINITE = (
    "must be a finite number (NaN and infinities are not; a number past ±1.8e308, such as "
    "1e309, reads as infinite)"
)
#: what a field of each of pydantic's scalar type errors takes (said with what came)
_SCALARS = {
    "float_type": "a number", "int_type": "a whole number", "bool_type": "true or false",
    "string_type": "a string",  # (was "Input should be a valid string": an API audit, 2026-12-08)
}  # fmt: skip


def _came(value: Any) -> str:
    """What a field of the wrong JSON type was given: its type and value (``null`` alone)."""
    return json_type(value) + ("" if value is None else f" ({clip(shown(value))})")


#: pydantic's error types of a number past a field's bound (said with the value)
_BOUNDS = frozenset({"less_than_equal", "greater_than_equal", "less_than", "greater_than"})


def json_type(value: Any) -> str:
    """What a decoded JSON value is, in JSON's words."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, dict):
        return "an object"
    return "a string" if isinstance(value, str) else "an array"


def validation_problem(raw: Sequence[Any], total: int = 0, partial: bool = False) -> JSONResponse:
    """The 422 of field errors; ``total``: how many were found where only the first few
    are in ``raw`` (``partial``: the look stopped there, so there may be more)."""
    listed = raw[:MAX_ERRORS]  # worded only where shown (a suggestion is a fuzzy search)
    errors = [{"location": _location(e.get("loc", ())), "message": _message(e)} for e in listed]
    detail = "; ".join(f"{e['location']}: {e['message']}" for e in errors[:3])
    total = max(total, len(raw))
    if total > 3 or partial:
        detail += f"; and {'at least ' if partial else ''}{total - 3} more"
    return problem(422, PoseError.title, detail, type_=PoseError.type_, errors=errors)


def install_handlers(app: FastAPI) -> None:
    @app.exception_handler(PoseError)
    async def _pose_error(request: Request, exc: PoseError) -> JSONResponse:
        refused(request.scope, exc)
        return error_response(exc)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        request.scope[REASON] = "invalid-request"
        return validation_problem(exc.errors())

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        if isinstance(exc, BodyError):
            refused(request.scope, exc.error)
            return error_response(exc.error)
        if isinstance(exc, BodyInvalid):
            request.scope[REASON] = "invalid-request"
            return exc.answer()
        title = detail = clip(exc.detail)
        with contextlib.suppress(ValueError):  # a detail of its own (service.files): the
            title = HTTPStatus(exc.status_code).phrase  # status's phrase, as about:blank's
        path = request.url.path
        if exc.status_code == 404 and path.endswith("/") and _is_route(request, path[:-1]):
            detail = f"no route {clip(path)}: the route is {clip(path[:-1])}, without the slash"
        elif exc.status_code == 404 and detail == title and (near := _near_route(request, path)):
            detail = f"no route {clip(path)} (did you mean {near}?)"  # (was "Not Found")
        headers = dict(exc.headers or {})
        allow = [m.strip() for m in headers.get("Allow", "").split(",") if m.strip()]
        if "GET" in allow and "HEAD" not in allow:  # every GET route answers HEAD too
            allow.append("HEAD")
            headers["Allow"] = ", ".join(allow)
        if exc.status_code == 405 and allow and detail == title:  # (was the phrase alone)
            takes = " and ".join([", ".join(allow[:-1]), allow[-1]] if len(allow) > 1 else allow)
            detail = f"{clip(request.method)} is not allowed on {clip(path)}: it takes {takes}"
        return problem(exc.status_code, title, detail, headers=headers)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        return internal_error(request.method, request.url.path)


def _near_route(request: Request, path: str) -> str | None:
    """The route whose path ``path`` is a slip of (:func:`core.text.near_name`, the rule of
    every other name a request gives: its case, or a letter or two off), else None; a path
    of more than 100 characters is none."""
    if len(path) > 100:
        return None
    return near_name(path, sorted(getattr(request.app.state, "route_paths", ())))


def _is_route(request: Request, path: str) -> bool:
    """Whether ``path`` is one of the app's routes (``service.app``: a 404 for it with a
    slash says so; a mount's path is none: ``/static`` answers nothing)."""
    return path in getattr(request.app.state, "route_paths", ())


def internal_error(method: str, path: str) -> JSONResponse:
    """Log the exception being handled and answer a 500 problem (no internals leak)."""
    log.exception("unhandled error on %s %s", method, clip(path))
    return problem(500, "Internal error", "an unexpected error occurred; see the server log")
