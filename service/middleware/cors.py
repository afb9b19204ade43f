"""CORS with problem+json rejections (Starlette answers a refused preflight in text)."""

from __future__ import annotations

from starlette.datastructures import Headers
from starlette.middleware.cors import CORSMiddleware
from starlette.responses import Response

from service.errors import CorsRejected, error_response


class ProblemCORS(CORSMiddleware):
    def preflight_response(self, request_headers: Headers) -> Response:
        response = super().preflight_response(request_headers)
        if response.status_code < 400:
            return response
        detail = bytes(response.body).decode("utf-8", "replace")
        answer = error_response(
            CorsRejected(f"{detail} (allowed origins are configured with POSE_CORS_ORIGINS)")
        )
        for key, value in response.headers.items():  # Starlette's Vary and allow-* headers
            if key not in ("content-length", "content-type"):
                answer.headers[key] = value
        return answer
