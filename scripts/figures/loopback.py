"""Shared by the docs/limits.md figure commands in this folder: a fresh ``pose-service``
(``tests/service/server.py``'s ``serve``) on a port of 18750-18799 on 127.0.0.1, requests
sent at once from threads, and what the answers and ``/proc`` say.

Not a command itself. Run the commands from the repository root, e.g.
``PYTHONPATH=. python scripts/figures/decode_memory.py``."""

from __future__ import annotations

import contextlib
import json
import socket
import sys
import tempfile
import threading
import time
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from scripts.rss_bursts import vm_mib as vm_mib  # noqa: E402  (its commands' name too)
from tests.service.server import Server, serve  # noqa: E402

PORTS = range(18750, 18800)
MODELS = ROOT / "models"
EXAMPLES = ROOT / "docs" / "examples"


def example(name: str) -> dict[str, Any]:
    """A request of ``docs/examples`` (a fresh copy each call)."""
    loaded: dict[str, Any] = json.loads((EXAMPLES / f"{name}.json").read_text())
    return loaded


def port() -> int:
    """A port of 18750-18799 nothing listens on."""
    for candidate in PORTS:
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", candidate))
            except OSError:
                continue
            return candidate
    raise RuntimeError("no free port in 18750-18799")


@contextlib.contextmanager
def server(**env: str) -> Iterator[Server]:
    """A fresh ``pose-service`` of this tree on 127.0.0.1, ready, its log in a temp folder;
    ``env`` adds environment variables, e.g. ``POSE_DEADLINE_SECONDS="2"``."""
    with (
        tempfile.TemporaryDirectory() as tmp,
        serve(MODELS, Path(tmp), True, (), port(), (), **env) as s,
    ):
        yield s


def reset_peak(pid: int) -> None:
    """VmHWM := VmRSS (``clear_refs``)."""
    Path(f"/proc/{pid}/clear_refs").write_text("5")


@dataclass
class Answer:
    status: int | str  # an HTTP status, or the client's exception
    sent: float  # perf_counter() when the request went
    seconds: float  # until the whole answer was read
    headers: dict[str, str]
    body: bytes

    def problem(self) -> str:
        """The problem's ``detail`` (or the body's start)."""
        try:
            return str(json.loads(self.body).get("detail", ""))
        except (ValueError, AttributeError):
            return self.body[:160].decode(errors="replace")


def at_once(
    s: Server, path: str, bodies: Sequence[bytes], headers: dict[str, str] | None = None,
    timeout: float = 120.0,
) -> list[Answer]:  # fmt: skip
    """POST each of ``bodies`` to ``path``, each from its own thread, all released at once;
    the answers in the bodies' order."""
    import http.client

    out: list[Answer | None] = [None] * len(bodies)
    start = threading.Barrier(len(bodies))

    def post(i: int) -> None:
        conn = http.client.HTTPConnection("127.0.0.1", s.port, timeout=timeout)
        start.wait()
        t = time.perf_counter()
        try:
            conn.request(
                "POST", path, body=bodies[i],
                headers={"content-type": "application/json", **(headers or {})},
            )  # fmt: skip
            resp = conn.getresponse()
            data = resp.read()
            head = {k.lower(): v for k, v in resp.getheaders()}
            out[i] = Answer(resp.status, t, time.perf_counter() - t, head, data)
        except Exception as exc:  # (a figure: what the client met)
            out[i] = Answer(type(exc).__name__, t, time.perf_counter() - t, {}, b"")
        finally:
            conn.close()

    threads = [threading.Thread(target=post, args=(i,)) for i in range(len(bodies))]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return [a for a in out if a is not None]


def statuses(answers: Sequence[Answer]) -> str:
    """``200×5 504×3``."""
    counts = Counter(str(a.status) for a in answers)
    return " ".join(f"{k}×{v}" for k, v in sorted(counts.items()))


def columnar_batches(
    n: int, size: int = 1024, passes: int | None = None, seed: int = 0,
    dataset: Path = ROOT / "data" / "poses.npz",
) -> list[bytes]:  # fmt: skip
    """``n`` distinct columnar batches of ``size`` real edits each (``bench``'s B1 pairs of
    the dataset's test split, both wrists moved to the goal pose's), ``options.passes``
    ``passes`` (None: the models' default)."""
    import numpy as np

    from bench.edits import edits_from_pairs, joint_idx, sample_pairs, test_split
    from bench.http_load import columnar_body
    from trainer.data.dataset import load_dataset

    data = test_split(load_dataset(dataset))
    a, b = sample_pairs(data, n * size, np.random.default_rng(seed))
    wrists = joint_idx(["left_wrist", "right_wrist"])
    edits = edits_from_pairs(data, a, b, [wrists] * (n * size))
    rows = [range(k * size, (k + 1) * size) for k in range(n)]
    return [json.dumps(columnar_body(edits, list(r), passes)).encode() for r in rows]


def host_load() -> str:
    """The host's 1-minute load average and cores, printed with every figure: this host is
    shared, and a timing taken beside other work says so."""
    import os

    return f"(host load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
