"""The engine time of a batch's items, per item, for ``service.limits.character_price``
(docs/characters.md, "A character item costs by its size"; docs/limits.md, "Work per
request"): what a work unit is worth in a batch of the costliest pose items and of plain
2-target ones, and what a character item of ``docs/examples/character_solve.json``'s
22-joint skeleton costs, grown by chains of joints to 122, 522 and 1,022 joints, in soft
reach without pins and as given (exact reach, two pins), beside its price.

``X-Compute-Time`` of ``POST /v1/solve/batch`` through the app in process (starlette's
test client, one compute thread, a 60 s deadline, an item limit of 8,192): the least of
``--rounds`` calls of each batch (the machine is shared: the least disturbed call is the
figure).

    python scripts/figures/character_price.py [--rounds 3]
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from service.limits import Pricing, character_price, max_item_price, price_of  # noqa: E402
from service.schemas import SolveOptions  # noqa: E402

EXAMPLES = ROOT / "docs" / "examples"


def grown(body: dict[str, Any], extra: int) -> dict[str, Any]:
    """``body``'s skeleton with ``extra`` joints more, in chains of ten under its last."""
    out = copy.deepcopy(body)
    joints = out["character"]["joints"]
    last = joints[-1]["name"]
    for k in range(extra):
        parent = last if k % 10 == 0 else f"x{k - 1}"
        joints.append({"name": f"x{k}", "parent": parent, "offset": [0.0, 0.01, 0.0]})
    return out


def main() -> None:
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import Settings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=ROOT / "models")
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()

    pose = json.loads((EXAMPLES / "solve.json").read_text())["pose"]
    wrists = [{"joint": j, "position": [c + 0.05 for c in pose[j]]}
              for j in ("left_wrist", "right_wrist")]  # fmt: skip
    costly = {"pose": pose, "targets": wrists, "pins": ["left_ankle", "right_ankle"],
              "options": {"reach": "exact", "passes": 4}}  # fmt: skip
    plain = {"pose": pose, "targets": wrists}
    exact = json.loads((EXAMPLES / "character_solve.json").read_text())
    exact["character"] = exact.pop("skeleton")  # (the batch's name of the alias's key)
    soft = {**exact, "options": {**exact.get("options", {}), "reach": "soft"}, "pins": []}
    settings = Settings(  # (an item limit for batches of 20 of the biggest characters)
        models_dir=args.models, deadline_seconds=60, compute_threads=1, max_batch_items=8192
    )
    with TestClient(create_app(settings, load_in_background=False)) as client:
        pricing = Pricing.of(client.app.state.pose.repository.engine)  # type: ignore[attr-defined]

        def per_item(items: list[dict[str, Any]]) -> float:
            """The least X-Compute-Time of the batch over the rounds, per item (ms)."""
            times = []
            for _ in range(args.rounds):
                r = client.post("/v1/solve/batch", json={"items": items})
                r.raise_for_status()
                times.append(float(r.headers["x-compute-time"].removesuffix("ms")))
            return min(times) / len(items)

        units = {
            "costliest pose items": (costly, max_item_price(pricing)),
            "plain 2-target pose items": (plain, price_of(SolveOptions(), False, pricing)),
        }
        unit_ms = []
        for name, (item, price) in units.items():
            ms = per_item([item] * 1024)
            unit_ms.append(ms / price)
            print(f"{name}: {ms:.3f} ms each, {price} units: {1e3 * ms / price:.2f} us a unit")
        for extra in (0, 100, 500, 1000):
            for name, base, slow in (("soft", soft, False), ("exact, 2 pins", exact, True)):
                body = grown(base, extra)
                n = len(body["character"]["joints"])
                ms = per_item([body] * 20)
                price = character_price(n, slow)
                print(f"{n} joints, {name}: {ms:.2f} ms each, priced {price} units "
                      f"({price * min(unit_ms):.2f} ms at the cheaper unit)")  # fmt: skip


if __name__ == "__main__":
    main()
