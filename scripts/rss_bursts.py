"""The memory a loopback ``pose-service`` keeps across bursts of the heaviest admitted loads
(docs/deploy.md, "Measured figures").

A burst is the container check's own (``tests/deploy/test_container.heavy_loads``: 64 item
lists of 1,024 exact-reach items, 42 columnar batches of 1,024 edits, 8 BVH solves and 8
inspects of 7.6 MB, each kind's requests all at once; most answer 504 or 429, as in the
check). VmRSS is read from ``/proc/<pid>/status`` once ready and 5 s after each burst,
VmHWM (the peak) at the end; one JSON line on stdout. The server inherits this process's
environment, so compare allocator settings by setting them here, e.g.

    .venv/bin/python scripts/rss_bursts.py --bursts 5
    MALLOC_ARENA_MAX=2 .venv/bin/python scripts/rss_bursts.py --bursts 5

Run it from the repository root (the server imports this tree's ``service``). Outside a
container the figures run 10-30 MiB above the image's (docs/deploy.md).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.deploy.test_container import heavy_loads  # noqa: E402
from tests.service.server import free_port  # noqa: E402


def vm_mib(pid: int, field: str) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith(f"{field}:"):
            return int(line.split()[1]) / 1024
    raise KeyError(field)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bursts", type=int, default=5)
    parser.add_argument("--models", default=str(ROOT / "models"))
    args = parser.parse_args()
    port = free_port()
    env = {
        **os.environ,
        "PYTHONPATH": str(ROOT),
        "POSE_HOST": "127.0.0.1",
        "POSE_PORT": str(port),
        "POSE_MODELS_DIR": args.models,
        "POSE_ORT_THREADS": "1",  # as deploy/k8s
        "OPENBLAS_NUM_THREADS": "1",  # as the image
        "POSE_LOG_LEVEL": "warning",
        "POSE_ACCESS_LOG": "false",
    }
    proc = subprocess.Popen(
        [sys.executable, "-c", "from service.cli import main; main()"],
        cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    loads = heavy_loads()
    out: dict[str, object] = {"MALLOC_ARENA_MAX": os.environ.get("MALLOC_ARENA_MAX")}
    after: list[int] = []
    codes: dict[int, int] = {}
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=120) as client:
            deadline = time.monotonic() + 180
            while True:
                try:
                    if client.get("/v2/health/ready").status_code == 200:
                        break
                except httpx.TransportError:
                    pass
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise SystemExit("the service did not become ready")
                time.sleep(0.2)
            time.sleep(1)
            out["rss_mib_ready"] = round(vm_mib(proc.pid, "VmRSS"))
            for _ in range(args.bursts):
                for path, body, n in loads:
                    got: list[int] = []

                    def one(path: str = path, body: bytes = body, got: list[int] = got) -> None:
                        head = {"content-type": "application/json"}
                        got.append(client.post(path, content=body, headers=head).status_code)

                    threads = [threading.Thread(target=one) for _ in range(n)]
                    for t in threads:
                        t.start()
                    for t in threads:
                        t.join()
                    for c in got:
                        codes[c] = codes.get(c, 0) + 1
                time.sleep(5)  # every answer sent: what stays is what the process keeps
                after.append(round(vm_mib(proc.pid, "VmRSS")))
            out["rss_mib_after_each_burst"] = after
            out["rss_mib_peak"] = round(vm_mib(proc.pid, "VmHWM"))
            out["codes"] = dict(sorted(codes.items()))
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(30)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
