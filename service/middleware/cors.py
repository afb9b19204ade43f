"""CORS with problem+json rejections (Starlette answers a refused preflight in text).

A refusal names what was refused and what is allowed, and where that is set: the origins
by ``POSE_CORS_ORIGINS``; the methods and request headers are the service's own
(:func:`service.middleware.install`), no setting. (Every refusal sent the operator to
``POSE_CORS_ORIGINS``, an allowed origin's refused method too: an audit, 2026-12-06.)
"""

from __future__ import annotations

from collections.abc import Collection
from typing import Any

from starlette.datastructures import Headers
from starlette.middleware.cors import CORSMiddleware
from starlette.responses import Response
from starlette.types import ASGIApp

from core.text import quoted
from service.errors import CorsRejected, error_response

_NAMES = 8  # refused header names a detail lists (then how many more)
_FIXED = "the service's own, no setting"


class ProblemCORS(CORSMiddleware):
    """Starlette's CORS, its refusals problems; each preflight counted in ``preflights``
    (``pose_cors_preflights_total{result}``: answered here, outside the request metrics,
    they were in no count)."""

    def __init__(
        self,
        app: ASGIApp,
        allow_origins: Collection[str] = (),
        allow_methods: Collection[str] = ("GET",),
        allow_headers: Collection[str] = (),
        expose_headers: Collection[str] = (),
        preflights: Any = None,
    ) -> None:
        super().__init__(app, allow_origins=allow_origins, allow_methods=allow_methods,
                         allow_headers=allow_headers, expose_headers=expose_headers)  # fmt: skip
        self._counted = (
            (preflights.labels("allowed"), preflights.labels("refused"))
            if preflights is not None
            else None
        )

    def preflight_response(self, request_headers: Headers) -> Response:
        response = super().preflight_response(request_headers)
        if self._counted is not None:
            self._counted[response.status_code >= 400].inc()
        if response.status_code < 400:
            return response
        detail = "; ".join(self.refusals(request_headers))
        answer = error_response(
            CorsRejected(detail or bytes(response.body).decode("utf-8", "replace"))
        )
        for key, value in response.headers.items():  # Starlette's Vary and allow-* headers
            if key not in ("content-length", "content-type"):
                answer.headers[key] = value
        return answer

    def refusals(self, request_headers: Headers) -> list[str]:
        """What a preflight asked that is not allowed, each with what is (Starlette's
        checks, in its order)."""
        out = []
        origin = request_headers["origin"]
        if not self.is_allowed_origin(origin=origin):
            out.append(
                f"Disallowed CORS origin {quoted(origin)} (allowed origins are configured "
                "with POSE_CORS_ORIGINS)"
            )
        method = request_headers["access-control-request-method"]
        if method not in self.allow_methods:
            allowed = ", ".join(self.allow_methods)
            out.append(
                f"Disallowed CORS method {quoted(method)}: the allowed methods are {allowed} "
                f"({_FIXED})"
            )
        asked = request_headers.get("access-control-request-headers")
        if asked is not None and not self.allow_all_headers:
            refused = [h.strip() for h in asked.lower().split(",")]
            refused = [h for h in refused if h not in self.allow_headers]
            if refused:
                names = ", ".join(quoted(h) for h in refused[:_NAMES])
                more = f" and {len(refused) - _NAMES} more" if len(refused) > _NAMES else ""
                allowed = ", ".join(self.allow_headers)
                out.append(
                    f"Disallowed CORS headers {names}{more}: the allowed request headers are "
                    f"{allowed} ({_FIXED})"
                )
        private = request_headers.get("access-control-request-private-network")
        if private is not None and not self.allow_private_network:
            out.append("Disallowed CORS private-network access (never allowed; no setting)")
        return out
