"""Request bodies: strict JSON, parsed and validated off the event loop when large.

FastAPI reads a JSON body with ``await request.json()`` and then validates it on the
event loop. :class:`BodyRoute` hands its endpoints a request whose ``json()`` returns the
body already validated into the endpoint's pydantic model (FastAPI passes an instance of
the model through unchanged), so that:

- malformed JSON is a 400 that says where (line, column), as are bodies that are not
  UTF-8, nest deeper than the parser's recursion limit or carry integers longer than
  Python converts; duplicate keys in an object are a 400 naming the key;
- bodies of ``INLINE_BYTES`` or more are decoded and validated in a worker thread
  (on one of the app's compute tokens, waited for no longer than the request's
  deadline), so a flood of big bodies never stalls the
  event loop (liveness keeps answering); so is a smaller one found wrong in more than
  ``INLINE_ERRORS`` places (validation is bounded: ``service.bounded``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Coroutine
from typing import Any, TypeVar

from fastapi import Request, Response
from fastapi.routing import APIRoute
from pydantic import BaseModel, ValidationError

from core.text import clip, quoted
from service import bounded, field_names, stepped
from service.errors import (
    BodyError,
    BodyInvalid,
    DeadlineExceeded,
    InvalidRequest,
    MalformedBody,
    PoseError,
    json_type,
)
from service.limits import Budget

NO_BODY = "the request has no body: send a JSON object"
BOM = b"\xef\xbb\xbf"  # UTF-8's byte order mark
INLINE_BYTES = 64 * 1024  # smaller bodies are parsed on the loop (a thread hop costs more)
#: Errors a body parsed on the loop has counted (~10 ms); one with more is read again in a
#: worker thread, counted up to ``service.bounded.COUNT_LIMIT`` (64 KiB hold ~40,000).
INLINE_ERRORS = 2_000
#: scope key: the body as decoded by the columnar fast path before it passed the body on
#: (``service.middleware.fastpath``), validated here as it is, not decoded again
DECODED = "pose.decoded"
T = TypeVar("T")


def _object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = dict(pairs)
    if len(out) != len(pairs):
        seen: set[str] = set()
        dup = next(k for k, _ in pairs if k in seen or seen.add(k))  # type: ignore[func-returns-value]
        raise MalformedBody(f"duplicate key {quoted(dup)} in a JSON object")
    return out


def decode(body: bytes) -> Any:
    """Strict JSON: UTF-8, no duplicate keys; every failure a ``MalformedBody`` that says
    where. (``NaN`` and ``Infinity`` tokens decode; the schemas then reject them by field.
    A UTF-8 byte order mark before the JSON is passed over: Windows tools write one, and
    it was a 400 telling the client to "decode using utf-8-sig".)"""
    if not body.strip():
        raise MalformedBody(NO_BODY)
    bom = len(BOM) if body.startswith(BOM) else 0  # (RFC 8259 8.1: a parser may ignore it)
    view = memoryview(body)[bom:]
    big = stepped.plan(view)  # (before the text: its arrays freed by then)
    try:
        text = str(view, "utf-8")
    except UnicodeDecodeError as exc:
        at = bom + exc.start
        raise MalformedBody(f"body is not UTF-8: byte 0x{body[at]:02x} at offset {at}") from None
    try:
        return stepped.loads(text, big, _object)  # (in steps: the GIL held briefly)
    except json.JSONDecodeError as exc:  # ("Unterminated string starting at": the place)
        what = exc.msg.removesuffix(" at").removesuffix(" starting")
        raise MalformedBody(
            f"malformed JSON at line {exc.lineno} column {exc.colno} (char {exc.pos}): {what}"
        ) from None
    except RecursionError:
        raise MalformedBody("JSON nested too deeply (arrays/objects within each other)") from None
    except ValueError as exc:  # integer longer than Python converts (4300 digits)
        raise MalformedBody(f"JSON number not accepted: {clip(str(exc), 80)}") from None


def parse(
    body: bytes, model: type[BaseModel] | None, settings: Any = None, limit: int | None = None
) -> Any:
    """Decode ``body`` and validate it into ``model`` (``settings``: the service's, in
    pydantic's validation context, with an error budget counting up to ``limit`` errors:
    ``service.bounded``); raises
    ``BodyError`` (a ``PoseError``: 400, or a validator's own, e.g. a batch over its item
    limit, 413) or ``BodyInvalid`` (422), the exceptions FastAPI's body reader lets
    through."""
    try:
        data = decode(body)
    except MalformedBody as exc:
        raise BodyError(exc) from None
    return validate(data, model, settings, limit)


def validate(
    data: Any, model: type[BaseModel] | None, settings: Any = None, limit: int | None = None
) -> Any:
    """:func:`parse`'s validation of the body ``data`` already decoded."""
    if model is None:
        return data
    if not isinstance(data, dict):  # (pydantic would name the model's Python class)
        forms = getattr(model, "BODY_FORMS", "a JSON object")
        raise BodyError(InvalidRequest(f"body: {forms} is required, not {json_type(data)}"))
    ctx = bounded.context(settings, limit)
    try:
        return model.model_validate(data, context=ctx)
    except ValidationError as exc:  # the first errors, and how many (service.bounded)
        shown, total, partial = bounded.errors_of(exc, ctx, data)
        field_names.offered(shown, model, data)  # (an unknown key's "did you mean")
        raise BodyInvalid(shown, total, partial) from None
    except PoseError as exc:  # a validator's refusal of the whole body
        raise BodyError(exc) from None


def in_worker(work: Callable[[], T]) -> Callable[[], T]:
    """``work`` to run in a worker thread: a refusal it raises leaves the thread worded
    (``BodyInvalid.answer``) and without the frames it passed through, so the decoded
    body those held, and the input its errors quote, are freed in the thread. Freed on
    the event loop, as they were, 1.3 million numbers took it 13 ms, as many strings
    50 ms."""

    def run() -> T:
        try:
            return work()
        except (BodyError, BodyInvalid) as exc:
            if isinstance(exc, BodyInvalid):
                exc.answer()
            else:
                exc.error.__traceback__ = exc.error.__context__ = None
            exc.__traceback__ = exc.__context__ = None
            raise exc from None

    return run


class _Request(Request):
    model: type[BaseModel] | None = None

    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            body = await self.body()
            state = getattr(self.app.state, "pose", None)
            settings = None if state is None else state.settings
            # decoded by the fast path: held here until read (then freed where it was read)
            decoded = [self.scope.pop(DECODED)] if DECODED in self.scope else []

            def read(limit: int | None = None) -> Any:
                if not decoded:
                    return parse(body, self.model, settings, limit)
                return validate(decoded.pop(), self.model, settings, limit)

            if len(body) < INLINE_BYTES:
                try:
                    self._json = read(INLINE_ERRORS)
                    return self._json
                except BodyInvalid as exc:
                    if not exc.partial:  # all counted; else counted on, off the loop
                        raise
            deadline = settings.deadline_seconds if settings is not None else math.inf
            try:
                self._json = await Budget(self, deadline).in_thread(
                    in_worker(read), "reading the body"
                )
            except DeadlineExceeded as exc:  # FastAPI lets only HTTPException through
                raise BodyError(exc) from None
        return self._json


class BodyRoute(APIRoute):
    """An ``APIRoute`` whose JSON body is read by :class:`_Request` (see the module doc)."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()
        annotation = self.body_field.field_info.annotation if self.body_field else None
        model = (
            annotation
            if isinstance(annotation, type) and issubclass(annotation, BaseModel)
            else None
        )
        request_class = type("BodyRequest", (_Request,), {"model": model})

        async def route_handler(request: Request) -> Response:
            req = request_class(request.scope, request.receive)
            if model is not None and not (await req.body()).strip():  # FastAPI would not
                raise BodyError(MalformedBody(NO_BODY))  # read it: 422 'Field required'
            return await handler(req)

        return route_handler
