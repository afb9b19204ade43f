"""The event loop while lone soft edits are solved (docs/limits.md, "Work per request": which
single edits are solved on the loop). A fresh ``pose-service`` of this tree; three clients
send one 15-target edit (its targets up to 1 m from the joints of the first sample pose, a
seeded draw; ``turn_search: false``) one after another for 6 s while a fourth asks
``/v2/health/live`` every 20 ms. Prints the liveness round trip (p50, max) and the edit's
``X-Compute-Time`` and solvers, for the edit in soft reach and then in exact reach.

    PYTHONPATH=. python scripts/figures/loop_stall.py
"""

from __future__ import annotations

import json
import random
import threading
import time

import numpy as np

from core.skeleton import JOINT_NAMES
from scripts.figures.loopback import ROOT, server

SECONDS = 6.0


def edit(reach: str) -> bytes:
    pose = json.loads((ROOT / "service/static/samples.json").read_text())["samples"][0]["pose"]
    rng = random.Random(11)
    joints = rng.sample(JOINT_NAMES, 15)
    targets = [{"joint": j, "position": [v + rng.uniform(-1, 1) for v in pose[j]]} for j in joints]
    options = {"turn_search": False, "reach": reach}
    return json.dumps({"pose": pose, "targets": targets, "options": options}).encode()


def main() -> None:
    with server() as s:
        for reach in ("soft", "exact"):
            body, stop, lat = edit(reach), time.monotonic() + SECONDS, []

            def client(body: bytes = body, stop: float = stop) -> None:
                while time.monotonic() < stop:
                    s.request("POST", "/v1/solve", body)

            def probe(stop: float = stop, lat: list[float] = lat) -> None:
                while time.monotonic() < stop:
                    t = time.perf_counter()
                    s.request("GET", "/v2/health/live")
                    lat.append(time.perf_counter() - t)
                    time.sleep(0.02)

            threads = [threading.Thread(target=client) for _ in range(3)]
            threads.append(threading.Thread(target=probe))
            for t in threads:
                t.start()
            for t in threads:
                t.join()
            _, headers, answer = s.request("POST", "/v1/solve", body)
            ms = 1e3 * np.array(lat)
            print(
                f"{reach}: liveness p50 {np.median(ms):.1f} ms, max {ms.max():.1f} ms "
                f"({len(ms)} probes); the edit's X-Compute-Time {headers['x-compute-time']}, "
                f"solvers {json.loads(answer)['solvers']}"
            )


if __name__ == "__main__":
    main()
