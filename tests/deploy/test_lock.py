"""constraints.txt locks every distribution the project installs, and both installs use it.

pyproject.toml keeps the ranges the code is written for; constraints.txt the exact
versions the suite last passed with (make's venv and the image install with ``-c``). An
unbounded range with no lock let a fresh clone or an image build pick up a new uvicorn,
whose httptools protocol service/transport.py relies on (an ops audit).
"""

from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[2]
LOCK = ROOT / "constraints.txt"
EXTRAS = ("service", "train", "dev")


def _pins() -> dict[str, str]:
    pins: dict[str, str] = {}
    for line in LOCK.read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            name, sep, version = line.partition("==")
            assert sep and re.fullmatch(r"[\w.]+", version), f"not an exact pin: {line!r}"
            pins[canonicalize_name(name)] = version
    return pins


def _requirements() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    return [
        Requirement(r) for r in project["dependencies"] + [d for e in EXTRAS for d in extras[e]]
    ]


def _closure(roots: list[Requirement]) -> set[str]:
    """Every distribution ``roots`` pull in, as installed here (their metadata's
    requirements, extras and markers followed)."""
    seen: set[tuple[str, frozenset[str]]] = set()
    todo = [(r.name, frozenset(r.extras)) for r in roots if r.marker is None or r.marker.evaluate()]
    while todo:
        name, extras = todo.pop()
        if (canonicalize_name(name), extras) in seen:
            continue
        seen.add((canonicalize_name(name), extras))
        for text in metadata.distribution(name).requires or []:
            req = Requirement(text)
            envs = [{"extra": e} for e in extras] or [{"extra": ""}]
            if req.marker is None or any(req.marker.evaluate(env) for env in envs):
                todo.append((req.name, frozenset(req.extras)))
    return {name for name, _ in seen}


def test_every_direct_dependency_is_locked_within_its_range() -> None:
    pins = _pins()
    for req in _requirements():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req.name} is not in constraints.txt: run `make lock`"
        assert req.specifier.contains(pins[name], prereleases=True), (req, pins[name])


def test_the_lock_covers_what_the_venv_pulled_in_and_the_venv_is_the_locked_one() -> None:
    """Every distribution installed for the project (direct or not, setuptools too, which
    torch needs at run time) is pinned, at the version installed: the suite runs on what
    the lock says."""
    pins = _pins()
    try:
        needed = _closure(_requirements())
    except metadata.PackageNotFoundError as exc:  # pragma: no cover - a partial venv
        pytest.skip(f"not every extra is installed here: {exc}")
    assert needed - pins.keys() == set(), "installed but not locked: run `make lock`"
    installed = {n: metadata.version(n).split("+")[0] for n in needed}
    assert {n: v for n, v in installed.items() if pins[n] != v} == {}, "venv off the lock"
    assert pins.keys() - needed == set(), "locked but no longer needed: run `make lock`"


def test_make_and_the_image_install_with_the_lock() -> None:
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^\$\(STAMP\): pyproject\.toml constraints\.txt$", makefile, re.M)
    assert "pip install --quiet -c constraints.txt -e '.[service,train,dev]'" in makefile
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    assert "COPY pyproject.toml constraints.txt ./" in dockerfile
    assert "-c constraints.txt -r /tmp/requirements.txt" in dockerfile
    allowed = (ROOT / ".dockerignore").read_text().splitlines()
    assert "!constraints.txt" in allowed
