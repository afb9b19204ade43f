"""The HTTP routes, one router per concern (mounted by ``service.app.create_app``)."""

from __future__ import annotations

from typing import Any

#: What any route's path may answer besides its own problems, declared on every operation
#: (``service.docs.document_problems`` gives them the problem+json body): a path no route
#: has, and a method its route does not take. Both are ``about:blank`` problems (their
#: status says it all, RFC 9457 section 4.2.1; docs/limits.md); neither was in the
#: contract, so a generated client had no type for their bodies (an API audit, 2026-12-07).
ROUTE_PROBLEMS: dict[int | str, dict[str, Any]] = {
    404: {
        "description": "No route at the path sent (a typo, or a trailing slash: the detail "
        "then names the route, `no route /v1/solve/: the route is /v1/solve, without the "
        "slash`); `about:blank`."
    },
    405: {
        "description": "A method the path's route does not take (a GET to a POST route); "
        "the `Allow` header lists those it does; `about:blank`.",
        "headers": {
            "Allow": {
                "description": "The methods the path takes (e.g. POST).",
                "schema": {"type": "string"},
            }
        },
    },
}
