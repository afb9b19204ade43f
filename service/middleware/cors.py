"""CORS with problem+json rejections (Starlette answers a refused preflight in text)."""

from __future__ import annotations

import json

from starlette.datastructures import Headers
from starlette.middleware.cors import CORSMiddleware
from starlette.responses import Response

from service.errors import PROBLEM_BASE, PROBLEM_JSON


class ProblemCORS(CORSMiddleware):
    def preflight_response(self, request_headers: Headers) -> Response:
        response = super().preflight_response(request_headers)
        if response.status_code < 400:
            return response
        detail = bytes(response.body).decode("utf-8", "replace")
        body = {
            "type": PROBLEM_BASE + "cors-rejected",
            "title": "CORS preflight rejected",
            "status": response.status_code,
            "detail": f"{detail} (allowed origins are configured with POSE_CORS_ORIGINS)",
        }
        keep = {
            k: v for k, v in response.headers.items() if k not in ("content-length", "content-type")
        }
        return Response(
            json.dumps(body), status_code=response.status_code, headers=keep,
            media_type=PROBLEM_JSON,
        )  # fmt: skip
