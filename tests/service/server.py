"""A real ``pose-service`` (uvicorn) on 127.0.0.1 for the fault and soak tests, and a
few raw HTTP helpers (http.client, sockets: no client library between test and server)."""

from __future__ import annotations

import contextlib
import http.client
import json
import os
import random
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from core.rest import rest_pose
from core.skeleton import JOINT_NAMES

REPO = Path(__file__).resolve().parents[2]


def free_port() -> int:
    """A loopback port free now. Under pytest-xdist (``make test``) each worker draws from a
    block of its own below the kernel's ephemeral range (where ``bind(0)`` and connections
    draw theirs): a port one worker checked is never another's before its server binds it."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    if worker.startswith("gw") and worker[2:].isdigit():
        low = 20_000 + 1000 * (int(worker[2:]) % 12)
        for port in random.sample(range(low, low + 1000), 1000):
            with socket.socket() as s, contextlib.suppress(OSError):
                s.bind(("127.0.0.1", port))
                return port
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@dataclass
class Server:
    proc: subprocess.Popen[bytes]
    port: int
    log: Path

    def request(
        self, method: str, path: str, body: bytes | None = None, timeout: float = 60.0
    ) -> tuple[int, dict[str, str], bytes]:
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=timeout)
        try:
            headers = {"content-type": "application/json"} if body is not None else {}
            conn.request(method, path, body=body, headers=headers)
            resp = conn.getresponse()
            return resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read()
        finally:
            conn.close()

    def cpu_seconds(self) -> float:
        """User + system CPU time of the server process so far."""
        fields = Path(f"/proc/{self.proc.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def rss_mib(self) -> float:
        for line in Path(f"/proc/{self.proc.pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
        return float("nan")

    def log_lines(self) -> list[dict[str, Any]]:
        out = []
        for line in self.log.read_text(errors="replace").splitlines():
            with contextlib.suppress(ValueError):
                out.append(json.loads(line))
        return out


@contextlib.contextmanager
def serve(
    models_dir: Path, tmp: Path, ready: bool = True, argv: Sequence[str] = (),
    port: int | None = None, wrap: Sequence[str] = (), **env: str,
) -> Iterator[Server]:  # fmt: skip
    """``pose-service`` (with ``argv``; run by the command ``wrap`` if given, e.g.
    ``unshare``) on ``port`` (default: a free one), once ready (or ``ready`` False:
    live); SIGTERM at the end."""
    port = port or free_port()
    log = tmp / f"server-{port}.log"
    environ = {**os.environ, "POSE_MODELS_DIR": str(models_dir), "POSE_PORT": str(port), **env}
    with log.open("wb") as sink:
        proc = subprocess.Popen(
            [*wrap, sys.executable, "-c", f"from service.cli import main; main({list(argv)!r})"],
            cwd=REPO, env=environ, stdout=sink, stderr=subprocess.STDOUT,
        )  # fmt: skip
    server = Server(proc, port, log)
    try:
        deadline = time.monotonic() + 120
        want = "/v2/health/ready" if ready else "/v2/health/live"
        while True:
            with contextlib.suppress(OSError):
                if server.request("GET", want, timeout=2)[0] == 200:
                    break
            assert proc.poll() is None, log.read_text()
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.05)  # (0.2 s: ~0.1 s late a start on average, ~50 starts a suite)
        yield server
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def peak_mib(pid: int | str = "self") -> Callable[[], int]:
    """Reset process ``pid``'s peak RSS (VmHWM, ``/proc``); the function returned reads
    its growth since (MiB)."""
    status = Path(f"/proc/{pid}/status")

    def read(key: str) -> int:
        line = next(x for x in status.read_text().splitlines() if x.startswith(key))
        return int(line.split()[1]) // 1024

    Path(f"/proc/{pid}/clear_refs").write_text("5")  # VmHWM := VmRSS
    start = read("VmRSS")
    return lambda: read("VmHWM") - start


@contextlib.contextmanager
def liveness_probed(server: Server, every: float, timeout: float) -> Iterator[list[float]]:
    """While the block runs, another client asks ``server``'s ``/v2/health/live`` every
    ``every`` seconds, each answer a 200 within ``timeout`` s; yields the answers'
    latencies (s), filled as they come. A probe that failed is raised when the block ends
    (an assertion in the probe's thread only warned, and stopped the probes)."""
    latencies: list[float] = []
    failed: list[BaseException] = []
    done = threading.Event()

    def probe() -> None:
        try:
            while not done.is_set():
                t = time.perf_counter()
                status = server.request("GET", "/v2/health/live", timeout=timeout)[0]
                assert status == 200, f"/v2/health/live answered {status}"
                latencies.append(time.perf_counter() - t)
                time.sleep(every)
        except BaseException as exc:  # (raised in the test's thread, below)
            failed.append(exc)

    prober = threading.Thread(target=probe)
    prober.start()
    try:
        yield latencies
    finally:
        done.set()
        prober.join()
    if failed:
        raise failed[0]


def solve_item(seed: int, exact: bool = True) -> dict[str, Any]:
    """A distinct solve: its own target set, weights and positions (so a batch of them
    shares no solver plan), exact reach, both ankles pinned."""
    rng = np.random.default_rng(seed)
    pose = rest_pose()
    joints = ["left_wrist", "right_wrist", "head", "left_knee", "right_knee", "spine2"]
    k = int(rng.integers(1, 4))
    chosen = rng.choice(joints, size=k, replace=False)
    return {
        "pose": dict(zip(JOINT_NAMES, pose.round(4).tolist(), strict=True)),
        "targets": [
            {
                "joint": str(j),
                "position": (pose[JOINT_NAMES.index(str(j))] + rng.normal(0, 0.4, 3)).tolist(),
                "weight": float(rng.uniform(0.5, 2.0)),
            }
            for j in chosen
        ],
        "pins": ["left_ankle", "right_ankle"],
        "options": {"reach": "exact" if exact else "soft"},
    }


def heavy_batch(n: int = 1024, seed: int = 0) -> bytes:
    return json.dumps({"items": [solve_item(seed + i) for i in range(n)]}).encode()
