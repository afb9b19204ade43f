"""What a clip's edit costs (docs/characters.md, "A clip: many frames in one call"): the
engine time per edit of ``--edits`` frames of a real file edited one request each
(``POST /v1/bvh/solve``, the file read, mapped and written once a request) against one
``POST /v1/bvh/solve/batch`` of the same edits (the file read and written once), beside
the price an edit has in a batch (``service.limits.edit_price``, ~6.4 us a unit).

Each edit drags the left wrist 10 cm up and 5 cm across from where it stands in its frame:
in soft reach, and in exact reach with both ankles pinned. ``X-Compute-Time`` through the
app in process (starlette's test client, one compute thread, a 60 s deadline), the least
of ``--rounds`` (the machine is shared: the least disturbed run is the figure). The files
are the character tests' (``tests.character_files.FILES``, extracted from ``--mocap``).

    python scripts/figures/bvh_clip.py [--edits 40] [--rounds 3] [--mocap ../shared/mocap]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from core.retarget import canonical_points  # noqa: E402
from core.skeleton import JOINT_INDEX  # noqa: E402
from service.bvh_models import BVHSolveRequest  # noqa: E402
from service.character_bvh import character_from_bvh, read_request_bvh  # noqa: E402
from service.limits import edit_price  # noqa: E402
from service.schemas import SolveOptions  # noqa: E402
from tests.character_files import FILES, extract_bvh  # noqa: E402

NAMES = ["bandai", "reactidle-6ch", "cmu-daz-salsa", "fair1-child-inches-zup"]
MOVE = np.array([0.05, 0.10, 0.0])  # metres, +Y up


def clip(text: str, name: str, n: int, reach: str) -> dict[str, Any]:
    """``n`` edits of consecutive frames from the file's test frame."""
    _, _, units, first = FILES[name]
    read = {"units": units} if units is not None else {}
    bvh = read_request_bvh(text)
    edits = []
    for f in range(first, min(first + n, bvh.num_frames)):
        ask = {"bvh": text, "frame": f, "targets": [{"joint": "head", "position": [0, 0, 0]}]}
        ch = character_from_bvh(bvh, BVHSolveRequest.model_validate({**ask, **read}), f)
        at = canonical_points(ch.skel, ch.pose, ch.jmap)[JOINT_INDEX["left_wrist"]]
        goal = at + ch.from_service(MOVE)
        pins = ["left_ankle", "right_ankle"] if reach == "exact" else []
        edits.append({"frame": f, "targets": [{"joint": "left_wrist", "position": goal.tolist()}],
                      "pins": pins, "options": {"reach": reach}})  # fmt: skip
    return {"bvh": text, **read, "edits": edits}


def ms(resp: Any) -> float:
    assert resp.status_code == 200, resp.text[:300]
    return float(resp.headers["x-compute-time"].removesuffix("ms"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--edits", type=int, default=40)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--mocap", type=Path, default=ROOT.parent / "shared" / "mocap")
    args = parser.parse_args()
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import Settings

    settings = Settings(compute_threads=1, deadline_seconds=60.0, max_batch_items=8192)
    app = create_app(settings, load_in_background=False)
    print("| file | joints | reach | edits | one request an edit, ms/edit | one clip, ms/edit "
          "| ratio | price of an edit (units, ~ms) |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp, TestClient(app) as c:
        files = extract_bvh(args.mocap, Path(tmp))
        for name in NAMES:
            text = files[name].read_text()
            joints = len(read_request_bvh(text, 0).joints)
            for reach in ("soft", "exact"):
                body = clip(text, name, args.edits, reach)
                head = {k: v for k, v in body.items() if k != "edits"}
                alone, together = [], []
                for _ in range(args.rounds):
                    alone.append(sum(ms(c.post("/v1/bvh/solve", json={**head, **e}))
                                     for e in body["edits"]))  # fmt: skip
                    together.append(ms(c.post("/v1/bvh/solve/batch", json=body)))
                n = len(body["edits"])
                one, both = min(alone) / n, min(together) / n
                price = edit_price(joints, SolveOptions(reach=reach), reach == "exact")
                print(
                    f"| {name} | {joints} | {reach} | {n} | {one:.2f} | {both:.2f} | "
                    f"{one / both:.2f} | {price} ({price * 6.4e-3:.1f}) |"
                )


if __name__ == "__main__":
    main()
