"""What the start-pose warnings' tests share (``up_warning``, ``floor_warning``,
``handedness_warning``): every form of ``/v1/solve`` says one warning alike, and the
real poses they are measured on."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_NAMES
from service.middleware import fastpath
from tests.conftest import REPO_ROOT


def examples() -> tuple[dict[str, Any], dict[str, Any]]:
    """The docs' solve example (exact reach, pins: the route), and its pose and targets
    alone (soft: the hot path's)."""
    example = json.loads((REPO_ROOT / "docs/examples/solve.json").read_text())
    return example, {"pose": example["pose"], "targets": example["targets"]}


def moved(body: dict[str, Any], fn: Callable[[np.ndarray], np.ndarray]) -> dict[str, Any]:
    """``body`` (the pose form) with ``fn`` applied to each point of its pose and targets
    (``[3]`` arrays)."""
    out = json.loads(json.dumps(body))
    out["pose"] = {n: fn(np.array(p)).tolist() for n, p in body["pose"].items()}
    for t in out["targets"]:
        t["position"] = fn(np.array(t["position"])).tolist()
    return out


def said_alike(client: Any, monkeypatch: pytest.MonkeyPatch, bodies: list[dict[str, Any]]
               ) -> list[dict[str, Any]]:  # fmt: skip
    """The answers to ``bodies`` (the pose form) as one batch's items, checked equal to
    each single answer, and each single answer's bytes the same from the route as from
    the hot path (a body the hot path leaves to the route)."""
    listed: list[dict[str, Any]] = client.post("/v1/solve/batch", json={"items": bodies}).json()[
        "items"
    ]
    assert listed == [client.post("/v1/solve", json=b).json() for b in bodies]
    fast = [client.post("/v1/solve", json=b).content for b in bodies]
    with monkeypatch.context() as m:
        m.setattr(fastpath, "pose_form", lambda body, data=None: None)
        m.setattr(fastpath, "plain", lambda data: None)
        assert [client.post("/v1/solve", json=b).content for b in bodies] == fast
    return listed


def columns(bodies: list[dict[str, Any]], **options: Any) -> dict[str, Any]:
    """The columnar form of one-target ``bodies`` (the pose form)."""
    out: dict[str, Any] = {
        "poses": [[v for n in JOINT_NAMES for v in b["pose"][n]] for b in bodies],
        "targets": {
            "joints": [bodies[0]["targets"][0]["joint"]],
            "positions": [b["targets"][0]["position"] for b in bodies],
        },
    }
    return {**out, "options": options} if options else out


def real_poses(split: str, small: Path) -> np.ndarray:
    """Every pose ``[N, 21, 3]`` of ``split`` (``test``, ``holdout``) of data/poses.npz where
    it is built (the whole measurement); else (a fresh clone: CI) of ``small``, the real
    dataset the session builds from a few clips of the archives (``small_dataset``): its
    TEST clips for ``test``, its other clips for ``holdout`` (real bodies too, if seen in
    training)."""
    full = REPO_ROOT / "data/poses.npz"
    data = np.load(full if full.is_file() else small)
    split_of = data["clip_split"][data["clip"]]
    mask = split_of == split if full.is_file() or split == "test" else split_of != "test"
    poses = data["positions"][mask].astype(np.float64)
    assert len(poses) > 100, split
    return poses
