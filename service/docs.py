"""The API's documentation: the OpenAPI schema says what the app does (every error is
problem+json, RFC 9457), and ``/docs`` renders it without any asset from the internet."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from fastapi import FastAPI
from fastapi.responses import HTMLResponse

from service.errors import WWW_AUTHENTICATE
from service.files import Files
from service.schemas import Problem

_PROBLEM_STATUS = {
    400: "Body is not valid JSON (the detail says where), not UTF-8, or has duplicate keys.",
    401: "Missing or wrong API key (only when POSE_API_KEY is set).",
    408: "The body did not arrive within the deadline (a stalled upload), or the request "
    "line and headers within POSE_HEAD_TIMEOUT_SECONDS of their first byte (`head-timeout`): "
    "the connection closes.",
    413: "Body or batch larger than the configured limit.",
    415: "Body is not application/json, or compressed (a Content-Encoding other than "
    "identity, a Transfer-Encoding other than chunked).",
    422: "Invalid request: the detail says which field and why.",
    429: "Too many requests in flight on this worker: retry after Retry-After seconds.",
    503: "Models not loaded yet (`not-ready`), or failed to load (`models-failed`, without "
    "Retry-After: the service does not retry; see /v2/health/ready), or shutting down, or too "
    "many connections open on the worker (`too-many-connections`, before the request is read).",
    504: "The request needed more than the deadline: send smaller batches.",
}

#: Statuses the HTTP protocol itself may answer on any route, before any app runs.
_PROTOCOL_STATUS = {
    400: "Bytes that are not an HTTP/1.1 request (`malformed-http`; the connection closes).",
    431: "Request line and headers over 64 KiB (`head-too-large`; the connection closes).",
    408: "Request line and headers not whole within POSE_HEAD_TIMEOUT_SECONDS of their first "
    "byte (`head-timeout`; the connection closes).",
    503: "Too many connections open on the worker (`too-many-connections`, POSE_MAX_CONNECTIONS"
    "; before the request is read; the connection closes).",
}

#: Headers of the answers (docs/limits.md, Headers).
_HEADERS = {
    "X-Request-ID": "The client's X-Request-ID (printable, at most 128 characters), else "
    "32 random hex digits.",
    "X-Total-Time": "The whole request, from arrival to the answer's headers (e.g. 0.612ms).",
}
_COMPUTE_TIME = "The engine's own work for the request (e.g. 0.274ms): not parsing or writing."
_RETRY_AFTER = "Seconds after which a retry may succeed."

#: The API key (POSE_API_KEY), when set: either header; the `{}` alternative is an
#: unguarded deployment (no key set), the default.
SECURITY_SCHEMES = {
    "ApiKey": {"type": "apiKey", "in": "header", "name": "X-API-Key"},
    "Bearer": {"type": "http", "scheme": "bearer"},
}


def operation_id(path: str, method: str, methods: int = 1) -> str:
    """A stable id from the path (``/v1/solve/batch`` -> ``solveBatch``, ``/v2/health/live``
    -> ``healthLive``; the method first where a path has several: ``getThing``): generated
    clients name their functions after it, so it must not follow the handlers' Python
    names (FastAPI's ``solve_batch_v1_solve_batch_post``). Unique ids: ``document_problems``
    checks."""
    words = [w for w in path.strip("/").split("/") if not (w[:1] == "v" and w[1:].isdigit())]
    words = [p for w in words for p in w.replace("-", "_").replace("{", "").replace("}", "")
             .split("_") if p] or ["root"]  # fmt: skip
    if methods > 1:
        words = [method.lower(), *words]
    return words[0] + "".join(w[:1].upper() + w[1:] for w in words[1:])


def _header(description: str, schema: dict[str, Any] | None = None) -> dict[str, Any]:
    return {"description": description, "schema": schema or {"type": "string"}}


#: components/headers: each described once, referred to by the answers that carry it.
HEADERS = {
    **{name: _header(text) for name, text in _HEADERS.items()},
    "X-Compute-Time": _header(_COMPUTE_TIME),
    "Retry-After": _header(_RETRY_AFTER, {"type": "integer"}),
    "WWW-Authenticate": _header(WWW_AUTHENTICATE),
}


def _answer_headers(code: str, method: str) -> list[str]:
    """The headers an answer declares: every answer carries X-Request-ID and X-Total-Time
    (declared on the 200s, said in docs/limits.md for all); then what a client acts on."""
    names = [*_HEADERS, *(["X-Compute-Time"] if method == "post" else [])] if code == "200" else []
    if code in ("429", "503", "504"):
        names.append("Retry-After")
    if code == "401":
        names.append("WWW-Authenticate")
    return names


#: Routes that answer without the models: their 503 is the shutdown's alone.
_NO_MODELS_503 = {
    "/v1/bvh/inspect": "Shutting down (this route needs no models: it answers while they "
    "load), or too many connections open on the worker (`too-many-connections`)."
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
        schema["components"]["securitySchemes"] = SECURITY_SCHEMES
        schema["components"]["headers"] = HEADERS
        components.update(components["Problem"].pop("$defs", {}))  # (FieldError)
        ref = {"$ref": "#/components/schemas/Problem"}
        for path, ops in schema["paths"].items():
            for method, op in ops.items():
                op["operationId"] = operation_id(path, method, len(ops))
                codes: list[int] = []
                if path.startswith("/v1/"):
                    post = [400, 401, 408, 413, 415, 422, 429, 503, 504]
                    codes = post if method == "post" else [401, 503]
                    op["security"] = [{}, {"ApiKey": []}, {"Bearer": []}]
                for code in codes:
                    text = _PROBLEM_STATUS[code]
                    if code == 503:
                        text = _NO_MODELS_503.get(path, text)
                    op["responses"][str(code)] = {"description": text}
                for code, text in _PROTOCOL_STATUS.items():
                    op["responses"].setdefault(str(code), {"description": text})
                for code, answer in op["responses"].items():
                    if int(code) >= 400:
                        answer["content"] = {"application/problem+json": {"schema": ref}}
                    if names := _answer_headers(code, method):
                        answer["headers"] = {
                            n: {"$ref": f"#/components/headers/{n}"} for n in names
                        }
        ids = [op["operationId"] for ops in schema["paths"].values() for op in ops.values()]
        if len(set(ids)) != len(ids):  # (a /v2 copy of a /v1 path would repeat one)
            raise RuntimeError(
                f"operation ids repeat: {sorted(i for i in ids if ids.count(i) > 1)}"
            )
        metrics = schema["paths"].get("/metrics", {}).get("get")
        if metrics is not None:  # Prometheus's text format
            plain = {"schema": {"type": "string"}}
            metrics["responses"]["200"]["content"] = {"text/plain; version=0.0.4": plain}
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

    app.mount("/docs/assets", Files(directory=VENDOR), name="docs-assets")
