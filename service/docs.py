"""The API's documentation: the OpenAPI schema says what the app does (every error is
problem+json, RFC 9457), and ``/docs`` renders it without any asset from the internet."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import HTMLResponse
from fastapi.staticfiles import StaticFiles

from service.schemas import Problem

_PROBLEM_STATUS = {
    400: "Body is not valid JSON (the detail says where), not UTF-8, or has duplicate keys.",
    401: "Missing or wrong API key (only when POSE_API_KEY is set).",
    408: "The body did not arrive within the deadline (a stalled upload): the connection closes.",
    413: "Body or batch larger than the configured limit.",
    415: "Body is not application/json, or compressed (a Content-Encoding other than "
    "identity, a Transfer-Encoding other than chunked).",
    422: "Invalid request: the detail says which field and why.",
    429: "Too many requests in flight on this worker: retry after Retry-After seconds.",
    503: "Models not loaded yet, or broken (see /v2/health/ready), or shutting down.",
    504: "The request needed more than the deadline: send smaller batches.",
}

#: Routes that answer without the models: their 503 is the shutdown's alone.
_NO_MODELS_503 = {
    "/v1/bvh/inspect": "Shutting down (this route needs no models: it answers while they load)."
}


def document_problems(app: FastAPI) -> None:
    """Make the schema say what the app does: errors are problem+json (RFC 9457)."""

    def openapi() -> dict[str, Any]:
        if app.openapi_schema:
            return app.openapi_schema
        from fastapi.openapi.utils import get_openapi

        schema = get_openapi(
            title=app.title, version=app.version, summary=app.summary, routes=app.routes
        )
        components = schema.setdefault("components", {}).setdefault("schemas", {})
        components["Problem"] = Problem.model_json_schema(
            ref_template="#/components/schemas/{model}"
        )
        for name in ("HTTPValidationError", "ValidationError"):
            components.pop(name, None)
        ref = {"$ref": "#/components/schemas/Problem"}
        for path, ops in schema["paths"].items():
            for method, op in ops.items():
                if not path.startswith("/v1/"):
                    continue
                post = [400, 401, 408, 413, 415, 422, 429, 503, 504]
                codes = post if method == "post" else [401, 503]
                for code in codes:
                    text = _PROBLEM_STATUS[code]
                    if code == 503:
                        text = _NO_MODELS_503.get(path, text)
                    op["responses"][str(code)] = {
                        "description": text,
                        "content": {"application/problem+json": {"schema": ref}},
                    }
        app.openapi_schema = schema
        return schema

    app.openapi = openapi  # type: ignore[method-assign]


VENDOR = Path(__file__).resolve().parent / "vendor" / "swagger-ui"
DOCS_CSP = (
    "default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
    "img-src 'self' data:; connect-src 'self'; object-src 'none'; base-uri 'none'; "
    "frame-ancestors 'none'; form-action 'none'"
)
_PAGE = """<!doctype html>
<html lang="en">
<head>
  <meta charset="utf-8">
  <title>Marionette pose service - API</title>
  <link rel="icon" href="data:,">
  <link rel="stylesheet" href="docs/assets/swagger-ui.css">
</head>
<body>
  <div id="swagger-ui"></div>
  <script src="docs/assets/swagger-ui-bundle.js"></script>
  <script src="docs/assets/init.js"></script>
</body>
</html>
"""


def mount_docs(app: FastAPI) -> None:
    """``/docs``: Swagger UI from the vendored, pinned ``swagger-ui-dist``
    (``scripts/vendor_swagger_ui.sh``), so it works offline; a strict CSP (no inline
    script, nothing from other origins)."""

    @app.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        return HTMLResponse(_PAGE, headers={"Content-Security-Policy": DOCS_CSP})

    app.mount("/docs/assets", StaticFiles(directory=VENDOR), name="docs-assets")
