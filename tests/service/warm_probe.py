"""Run as a script (``python -m tests.service.warm_probe MODELS``) by ``test_warm.py``: start
the app as the service does (models loaded, kernels warmed, the warm-up solve), note every
compiled kernel's signatures, post every kind of request a user sends, and print as JSON
the signatures those requests added: each one a kernel compiled (or loaded) on a user's
request instead of at start."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from core import compiled, compiled_characters, compiled_fabrik
from core.skeleton import JOINT_NAMES

EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"
FIVE = ["head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]


def signatures() -> dict[str, set[str]]:
    """Every compiled kernel's signatures so far, by name."""
    out = {}
    for mod in (compiled, compiled_fabrik, compiled_characters):
        for name in dir(mod):
            sigs = getattr(getattr(mod, name), "signatures", None)
            if sigs is not None:
                out[f"{mod.__name__}.{name}"] = {str(s) for s in sigs}
    return out


def requests() -> list[tuple[str, dict[str, Any]]]:
    """Routes and bodies: the docs' examples, and the example edit asked every way."""
    out = [
        ("/v1/solve", "solve.json"), ("/v1/solve", "solve_character.json"),
        ("/v1/character/solve", "character_solve.json"), ("/v1/complete", "complete.json"),
        ("/v1/solve/batch", "batch.json"), ("/v1/bvh/solve", "bvh_solve.json"),
    ]  # fmt: skip
    bodies = [(route, json.loads((EXAMPLES / f).read_text())) for route, f in out]
    base = json.loads((EXAMPLES / "solve.json").read_text())
    pose = np.array([base["pose"][j] for j in JOINT_NAMES])
    edits = []
    for joints in (["left_wrist"], ["pelvis"], ["left_elbow", "right_knee"], FIVE):
        for options in (
            {}, {"reach": "exact"}, {"method": "fabrik"}, {"turn_search": False},
            {"passes": 1}, {"passes": 3, "carry": 0.0}, {"preserve_bone_lengths": False},
        ):  # fmt: skip
            # (the raw answer has no pins: they keep the bone lengths, a 422 beside it)
            for pins in ([], ["right_ankle"])[: 1 if "preserve_bone_lengths" in options else 2]:
                far = 2.0 if joints == ["pelvis"] else 0.3
                body = copy.deepcopy(base)
                body["targets"] = [
                    {"joint": j, "position": (pose[JOINT_NAMES.index(j)] + far).tolist()}
                    for j in joints
                ]
                body["pins"] = [p for p in pins if p not in joints]
                body["options"] = options
                edits.append(body)
    bodies += [("/v1/solve", b) for b in edits]
    bodies.append(("/v1/solve/batch", {"items": edits}))
    for joints in (["left_wrist", "right_wrist"], FIVE):
        idx = [JOINT_NAMES.index(j) for j in joints]
        goals = (pose[idx] + 0.2).reshape(-1).tolist()
        for n in (1, 3):
            columns = {"joints": joints, "positions": [goals] * n}
            body = {"poses": [pose.reshape(-1).tolist()] * n, "targets": columns, "options": {}}
            bodies.append(("/v1/solve/batch", body))
    return bodies


def main(models: str) -> None:
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import Settings

    app = create_app(Settings(models_dir=Path(models)), load_in_background=False)
    with TestClient(app, raise_server_exceptions=False) as client:
        before = signatures()
        statuses = []
        for route, body in requests():
            statuses.append(client.post(route, json=body).status_code)
        after = signatures()
    added = {k: sorted(v - before.get(k, set())) for k, v in after.items()}
    print(json.dumps({"added": {k: v for k, v in added.items() if v}, "statuses": statuses}))


if __name__ == "__main__":
    main(sys.argv[1])
