"""The service's files (``service/files.py``: the editor's page and ``/static``, the docs'
``/docs/assets``) through the real app: their refusals are problems like every other
answer's, and their requests are counted and advised as what they are (an adversarial
audit, 2026-12-06, defects 3-5)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest
from starlette.routing import Mount

from service.docs import VENDOR
from service.editor import EDITOR_PAGE, STATIC_DIR
from tests.conftest import make_client
from tests.service.test_api import assert_problem

#: A file under each mount the app has, and its size.
FILES = {
    "/static": ("editor.js", (STATIC_DIR / "editor.js").stat().st_size),
    "/docs/assets": ("init.js", (VENDOR / "init.js").stat().st_size),
}


def mounts(client: Any) -> list[str]:
    """The paths the app mounts (every one must be in ``FILES``)."""
    paths = [r.path for r in client.app.routes if isinstance(r, Mount)]
    assert set(paths) == set(FILES), paths
    return paths


def served(client: Any) -> list[tuple[str, int]]:
    """Every kind of file the app serves: one under each mount, and the editor's page."""
    out = [(f"{m}/{FILES[m][0]}", FILES[m][1]) for m in mounts(client)]
    return [*out, ("/editor", EDITOR_PAGE.stat().st_size)]


@pytest.mark.parametrize("method", ["GET", "HEAD"])
def test_a_range_past_a_files_end_is_a_416_problem_with_its_size(client: Any, method: str) -> None:
    """Was Starlette's 416 in text/plain with an empty body."""
    for path, size in served(client):
        r = client.request(method, path, headers={"Range": f"bytes={size + 10}-"})
        assert r.status_code == 416, (path, r.text)
        assert r.headers["content-type"] == "application/problem+json", path
        assert r.headers["content-range"] == f"bytes */{size}", path
        assert "x-request-id" in r.headers and "x-total-time" in r.headers
        if method == "GET":
            body = assert_problem(r, 416, f"'bytes={size + 10}-'", f"{size} bytes")
            assert body["type"].endswith("/range-not-satisfiable") and body["title"]


@pytest.mark.parametrize(
    ("range_", "why"),
    [
        ("bytes=5-1", "a range ends before it starts"),
        ("bytes=-", "it names no range"),
        ("bytes", "not a unit and ranges"),
    ],
)
def test_a_malformed_range_is_a_400_problem_that_says_why(
    client: Any, range_: str, why: str
) -> None:
    """Was Starlette's 400 in text/plain ("Range header: start must be less than end")."""
    for path, _ in served(client):
        r = client.get(path, headers={"Range": range_})
        body = assert_problem(r, 400, repr(range_), why)
        assert body["type"].endswith("/malformed-range"), body


def test_a_range_in_another_unit_is_ignored_and_the_whole_file_served(client: Any) -> None:
    """RFC 9110, section 14.2: an origin server MUST ignore a Range of a unit it does not
    understand (Starlette's answer was a 400)."""
    for path, size in served(client):
        whole = client.get(path)
        assert len(whole.content) == size, path
        r = client.get(path, headers={"Range": "items=0-1"})
        assert r.status_code == 200 and "content-range" not in r.headers, (path, r.headers)
        assert r.content == whole.content, path


def test_a_satisfiable_range_is_still_served(client: Any) -> None:
    for path, size in served(client):
        r = client.get(path, headers={"Range": "bytes=0-9"})
        assert r.status_code == 206 and len(r.content) == 10, path
        assert r.headers["content-range"] == f"bytes 0-9/{size}"


def test_requests_under_a_mount_are_counted_under_the_mount(models_dir: Path) -> None:
    """``/static/editor`` was counted as a 404 of the editor's page ``/editor``,
    ``/static/`` and ``/docs/assets/`` as 404s of ``/``, and every file served as
    ``unmatched`` (the label of requests that matched no route). Now each is counted
    under its mount, one label per mount, whatever the file."""
    with make_client(models_dir) as c:
        for m in mounts(c):
            name, _ = FILES[m]
            assert c.get(f"{m}/").status_code == 404
            assert c.get(f"{m}/editor").status_code == 404
            assert c.get(f"{m}/nothing/here.js").status_code == 404
            first = c.get(f"{m}/{name}")
            assert first.status_code == 200
            etag = {"If-None-Match": first.headers["etag"]}
            assert c.get(f"{m}/{name}", headers=etag).status_code == 304
            assert c.head(f"{m}/{name}").status_code == 200
            assert c.get(f"{m}/{name}", headers={"Range": "bytes=0-1"}).status_code == 206
            assert c.get(f"{m}/{name}", headers={"Range": "bytes=9-1"}).status_code == 400
        assert c.get("/static").status_code == 404  # no mount's path (nor any route's)
        text = c.get("/metrics").text
        templates = {getattr(r, "path", "") for r in c.app.routes}
    counted = re.findall(
        r'^pose_requests_total\{route="([^"]*)",status="(\d+)"\} (\S+)', text, re.M
    )
    got = {(route, status): float(n) for route, status, n in counted}
    for m in FILES:
        assert got[(m, "404")] == 3.0, got
        assert got[(m, "200")] == 2.0 and got[(m, "304")] == 1.0, got
        assert got[(m, "206")] == 1.0 and got[(m, "400")] == 1.0, got
        assert f'pose_rejections_total{{reason="malformed-range",route="{m}"}} 1.0' in text
    assert got[("unmatched", "404")] == 1.0, got  # /static itself
    assert ("/", "404") not in got and ("/editor", "404") not in got, got
    assert {route for route, _ in got} <= templates | {"unmatched"}, got  # no label per file


def test_a_mounts_own_path_is_a_plain_404_that_advises_nothing(client: Any) -> None:
    """``/static/`` advised "the route is /static, without the slash", itself a 404."""
    for m in mounts(client):
        assert_problem(client.get(m), 404)
        for path in (f"{m}/", f"{m}//"):
            body = assert_problem(client.get(path), 404)
            assert body["detail"] == body["title"] == "Not Found", (path, body)


def test_a_files_path_with_a_trailing_slash_is_a_404_naming_the_file(client: Any) -> None:
    """``/static/editor.js/`` was served (200), where the docs say a path with a trailing
    slash is a 404 naming what is there; the relative URLs of a file served so resolve
    under ``editor.js/``."""
    for path, _ in served(client):
        if path == "/editor":  # the page's own redirect (test_request_edges)
            continue
        for method in ("GET", "HEAD"):
            r = client.request(method, path + "/")
            assert r.status_code == 404 and r.headers["content-type"] == "application/problem+json"
        body = assert_problem(client.get(path + "/"), 404)
        assert body["title"] == "Not Found", body
        assert body["detail"] == f"no file {path}/: the file is {path}, without the slash"
        assert client.get(path).status_code == 200  # the advice is true
        assert_problem(client.get(path + "//"), 404, "Not Found")
    assert_problem(client.get("/static/editor/api.js/"), 404, "the file is /static/editor/api.js")
    assert_problem(client.get("/static/editor/"), 404, "Not Found")  # a directory: no file
