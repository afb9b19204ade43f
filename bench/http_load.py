"""HTTP load against the real service: ``pose-service`` (uvicorn) as a subprocess on a
free 127.0.0.1 port, a bounded raw-asyncio HTTP/1.1 load generator, RSS from /proc.

Loopback only; every run is bounded in request count and in time."""

from __future__ import annotations

import asyncio
import base64
import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx
import numpy as np
import numpy.typing as npt

from bench.edits import Edits
from core.skeleton import JOINT_NAMES

Json = dict[str, Any]
HOST = "127.0.0.1"


@dataclass(frozen=True)
class Server:
    url: str
    pid: int
    command: str


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


def rss_kb(pid: int) -> int:
    """VmRSS of a process (kB) from /proc/<pid>/status; -1 if unavailable."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    except OSError:
        pass
    return -1


def _server_command(models: Path, port: int) -> list[str]:
    script = Path(sys.executable).parent / "pose-service"
    if not script.exists() and shutil.which("pose-service"):
        script = Path(str(shutil.which("pose-service")))
    base = (
        [str(script)]
        if script.exists()
        else [sys.executable, "-c", "from service.cli import main; main()"]
    )
    return [*base, "--host", HOST, "--port", str(port), "--models-dir", str(models)]


@contextlib.contextmanager
def serve(
    models: Path, *, ready_timeout: float = 90.0, log: Path | None = None
) -> Iterator[Server]:
    """Start the service, wait for /v2/health/ready, yield, then terminate it."""
    port = free_port()
    cmd = _server_command(models, port)
    env = {
        **os.environ,
        "POSE_ORT_THREADS": "1",
        "POSE_LOG_LEVEL": "warning",
        "POSE_ACCESS_LOG": "false",
        "OMP_NUM_THREADS": "1",
    }
    sink = open(log, "wb") if log else subprocess.DEVNULL  # noqa: SIM115
    proc = subprocess.Popen(cmd, env=env, stdout=sink, stderr=subprocess.STDOUT)
    url = f"http://{HOST}:{port}"
    try:
        deadline = time.monotonic() + ready_timeout
        with httpx.Client(timeout=2.0) as client:
            while True:
                if proc.poll() is not None:
                    raise RuntimeError(f"server exited with {proc.returncode}: {' '.join(cmd)}")
                detail = ""
                try:
                    ready = client.get(f"{url}/v2/health/ready")
                    if ready.status_code == 200:
                        break
                    detail = ready.text
                except httpx.TransportError as exc:
                    detail = repr(exc)
                if time.monotonic() > deadline:
                    raise RuntimeError(
                        f"server not ready after {ready_timeout:.0f} s: {detail[:500]}"
                    )
                time.sleep(0.1)
        yield Server(
            url, proc.pid, " ".join(Path(c).name if i == 0 else c for i, c in enumerate(cmd))
        )
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
        if log:
            sink.close()  # type: ignore[union-attr]


def request_body(
    start: np.ndarray, joints: np.ndarray, targets: np.ndarray, passes: int | None = None,
    mirror: bool | None = None,
) -> Json:  # fmt: skip
    """A pose-form body; ``passes``, ``mirror``: ``options.passes``, ``options.mirror``
    (None: the models' default)."""
    return {
        "pose": {n: [float(v) for v in start[i]] for i, n in enumerate(JOINT_NAMES)},
        "targets": [
            {"joint": JOINT_NAMES[int(j)], "position": [float(v) for v in t]}
            for j, t in zip(joints, targets, strict=True)
        ],
        "options": _options(passes, mirror),
    }


def _options(passes: int | None, mirror: bool | None = None) -> Json:
    o: Json = {"method": "neural", "preserve_bone_lengths": True, "reach": "soft"}
    o = o if passes is None else {**o, "passes": passes}
    return o if mirror is None else {**o, "mirror": mirror}


def columnar_body(
    edits: Edits,
    rows: Sequence[int],
    passes: int | None = None,
    mirror: bool | None = None,
    packed: bool = False,
) -> Json:
    """The columnar form of the edits ``rows`` (docs/limits.md): one row of 63 numbers per
    pose, target joints per item, one row of 3K numbers per item; ``packed``: the poses
    and the targets' positions as packed columns (base64 of little-endian float64)."""
    poses = edits.start[np.asarray(rows)].reshape(len(rows), -1)
    goals = np.stack([np.asarray(edits.targets[i]).reshape(-1) for i in rows])
    return {
        "poses": _packed(poses) if packed else poses.tolist(),
        "targets": {
            "joints": [[JOINT_NAMES[int(j)] for j in edits.joints[i]] for i in rows],
            "positions": _packed(goals) if packed else goals.tolist(),
        },
        "options": _options(passes, mirror),
    }


def _packed(rows: npt.NDArray[np.floating[Any]]) -> str:
    """``rows`` as a packed column (``service.columnar.PACKED``)."""
    return base64.b64encode(np.ascontiguousarray(rows, dtype="<f8").tobytes()).decode()


def bodies(edits: Edits, passes: int | None = None, mirror: bool | None = None) -> list[Json]:
    return [
        request_body(edits.start[i], edits.joints[i], edits.targets[i], passes, mirror)
        for i in range(len(edits))
    ]


async def _exchange(
    reader: asyncio.StreamReader, writer: asyncio.StreamWriter, request: bytes
) -> int:
    """Send one pre-built HTTP/1.1 request on a kept-alive connection; read the whole
    response; return its status."""
    writer.write(request)
    await writer.drain()
    status, fields = _parse_head(await reader.readuntil(b"\r\n\r\n"))
    await reader.readexactly(int(fields.get(b"content-length", b"0")))
    return status


def _parse_head(head: bytes) -> tuple[int, dict[bytes, bytes]]:
    """A response head's status and its header fields (lower-cased names)."""
    fields = {}
    for line in head.split(b"\r\n")[1:]:
        name, _, value = line.partition(b":")
        fields[name.strip().lower()] = value.strip()
    return int(head.split(b" ", 2)[1]), fields


async def _load(
    url: str,
    payloads: Sequence[bytes],
    concurrency: int,
    max_requests: int,
    max_seconds: float,
) -> Json:
    """A bounded closed-loop load: ``concurrency`` kept-alive connections, each sending
    its next request when the previous answer is in. The client is a few lines of raw
    asyncio HTTP/1.1 (requests pre-built, answers read but not parsed), so it costs the
    shared 2 CPUs little next to the server."""
    latencies: list[float] = []
    errors = 0
    issued = 0
    built = [_request_bytes(url, body) for body in payloads]
    host, port, requests = built[0][0], built[0][1], [r for _, _, r in built]
    t_end = time.perf_counter() + max_seconds

    async def worker() -> None:
        nonlocal issued, errors
        reader, writer = await asyncio.open_connection(host, port)
        try:
            while issued < max_requests and time.perf_counter() < t_end:
                request = requests[issued % len(requests)]
                issued += 1
                t0 = time.perf_counter()
                try:
                    ok = await asyncio.wait_for(_exchange(reader, writer, request), 60.0) == 200
                except (TimeoutError, OSError, asyncio.IncompleteReadError):
                    ok = False
                    writer.close()
                    reader, writer = await asyncio.open_connection(host, port)
                latencies.append(time.perf_counter() - t0)
                errors += not ok
        finally:
            writer.close()

    t0 = time.perf_counter()
    await asyncio.gather(*(worker() for _ in range(concurrency)))
    return _summary(concurrency, latencies, errors, time.perf_counter() - t0)


def _summary(
    concurrency: int, latencies: Sequence[float], errors: int, seconds: float
) -> dict[str, Any]:
    """Requests, errors, rate and latency percentiles (ms) of one load run."""
    ms = np.asarray(latencies) * 1e3
    return {
        "concurrency": concurrency,
        "requests": len(latencies),
        "errors": errors,
        "seconds": seconds,
        "rps": len(latencies) / seconds,
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "mean_ms": float(ms.mean()),
    }


def load(
    url: str, payloads: Sequence[bytes], concurrency: int, max_requests: int, max_seconds: float
) -> Json:
    """Concurrency 1: :func:`_load_one` (a blocking socket: the least client time per
    request). More: :func:`_load` on uvloop when installed (uvicorn serves on uvloop too),
    else on asyncio."""
    if concurrency == 1:
        return _load_one(url, payloads, max_requests, max_seconds)
    run = _loop_runner()
    out: Json = run(_load(url, payloads, concurrency, max_requests, max_seconds))
    return out


def _request_bytes(url: str, body: bytes) -> tuple[str, int, bytes]:
    parsed = urlsplit(url)
    host, port = parsed.hostname or HOST, parsed.port or 80
    head = (
        f"POST {parsed.path} HTTP/1.1\r\nHost: {host}:{port}\r\n"
        f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n\r\n"
    )
    return host, port, head.encode() + body


def _load_one(
    url: str, payloads: Sequence[bytes], max_requests: int, max_seconds: float, gap: float = 0.0
) -> Json:
    """One kept-alive connection on a blocking socket (TCP_NODELAY), each request sent
    when the previous answer is in and (``gap`` s) no sooner than ``gap`` after the previous
    one was sent; also the server's own ``X-Total-Time`` (from the request's arrival in the
    app to its answer's headers) and ``X-Compute-Time`` (the engine's)."""
    requests = [_request_bytes(url, body) for body in payloads]
    host, port = requests[0][0], requests[0][1]
    latencies: list[float] = []
    server: list[float] = []
    compute: list[float] = []
    errors = 0
    sent = -gap
    sock = socket.create_connection((host, port), timeout=60.0)
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    buf = b""
    t_start = time.perf_counter()
    t_end = t_start + max_seconds
    try:
        while len(latencies) < max_requests and time.perf_counter() < t_end:
            request = requests[len(latencies) % len(requests)][2]
            while gap and time.perf_counter() < sent + gap:  # (the pace: sleep, not spin)
                time.sleep(max(0.0, min(sent + gap - time.perf_counter(), 1e-3)))
            t0 = sent = time.perf_counter()
            sock.sendall(request)
            while b"\r\n\r\n" not in buf:
                chunk = sock.recv(1 << 16)
                if not chunk:
                    raise RuntimeError("the server closed the connection")
                buf += chunk
            head, _, rest = buf.partition(b"\r\n\r\n")
            status, fields = _parse_head(head)
            length = int(fields.get(b"content-length", b"0"))
            parts, have = [rest], len(rest)
            while have < length:
                chunk = sock.recv(max(1 << 16, length - have))
                if not chunk:
                    raise RuntimeError("the server closed the connection")
                parts.append(chunk)
                have += len(chunk)
            data = b"".join(parts)
            buf = data[length:]
            latencies.append(time.perf_counter() - t0)
            errors += status != 200
            for name, got in ((b"x-total-time", server), (b"x-compute-time", compute)):
                value = fields.get(name, b"").removesuffix(b"ms")
                if value:
                    got.append(float(value))
    finally:
        sock.close()
    return {
        **_summary(1, latencies, errors, time.perf_counter() - t_start),
        "server_p50_ms": float(np.percentile(server, 50)) if server else None,
        "compute_p50_ms": float(np.percentile(compute, 50)) if compute else None,
        "gap_ms": gap * 1e3,
        "client": "blocking socket",
    }


def _loop_runner() -> Any:
    try:
        import uvloop
    except ImportError:
        return asyncio.run
    return uvloop.run


def client_loop() -> str:
    return "uvloop" if _loop_runner() is not asyncio.run else "asyncio"


def _batch_row(b: Json, batch_size: int, request_bytes: int) -> Json:
    return {
        "batch_size": batch_size,
        "batches": b["requests"],
        "concurrency": 1,
        "errors": b["errors"],
        "p50_ms": b["p50_ms"],
        "seconds": b["seconds"],
        "poses_per_s": b["requests"] * batch_size / b["seconds"],
        "request_bytes": request_bytes,
    }


#: Issue 14's HTTP goals (loopback, one worker).
SOLVE_P50_MS = 0.5
BATCH_POSES_PER_S = 30_000.0
#: A drag's pace: an editor sends its next edit a display frame (60 Hz) after the last.
DRAG_GAP_S = 1.0 / 60.0


def goal_rows(http: Json | None) -> list[tuple[str, str, str, bool | None]]:
    """Issue 14's HTTP goals as (name, target, measured, met) from :func:`run_http`'s
    result (``met`` None: not measured). The goals judge the default configuration (the
    models' passes, what users get); the ``passes: 1`` figure is shown beside it."""
    http = http or {}
    one = next((r for r in http.get("solve", []) if r["concurrency"] == 1), None)
    p1, col1 = http.get("solve_passes1"), http.get("batch_columnar_passes1")
    p_m, col_m = http.get("solve_no_mirror"), http.get("batch_columnar_no_mirror")
    paced = http.get("solve_paced")
    at1 = f"; {p1['p50_ms']:.3f} ms at passes=1" if p1 else ""
    at1 += f"; {p_m['p50_ms']:.3f} ms with mirror: false" if p_m else ""
    at1 += (
        f"; {paced['p50_ms']:.3f} ms at a drag's pace, a request every "
        f"{paced['gap_ms']:.1f} ms" if paced else ""
    )  # fmt: skip
    rows: list[tuple[str, str, str, bool | None]] = [
        (
            "HTTP /v1/solve p50 at concurrency 1 (loopback, the models' passes)",
            f"≤ {SOLVE_P50_MS} ms",
            "–" if one is None else f"{one['p50_ms']:.3f} ms (p99 {one['p99_ms']:.2f}{at1})",
            None if one is None else one["p50_ms"] <= SOLVE_P50_MS,
        )
    ]
    col, items = http.get("batch_columnar"), http.get("batch")
    packed = http.get("batch_columnar_packed")
    also = f"; item list {items['poses_per_s']:,.0f}" if items else ""
    also += f"; {col1['poses_per_s']:,.0f} at passes=1" if col1 else ""
    also += f"; {col_m['poses_per_s']:,.0f} with mirror: false" if col_m else ""
    if packed:
        also += f"; packed columns (base64 float64) {packed['poses_per_s']:,.0f}"
    # judged on the faster of the two columnar forms the contract documents (JSON numbers,
    # packed columns): both are shown
    best = max((r["poses_per_s"] for r in (col, packed) if r), default=None)
    rows.append(
        (
            "HTTP /v1/solve/batch poses/s (columnar form: JSON numbers, then packed; "
            f"{col['batch_size'] if col else '–'} per request)",
            f"≥ {BATCH_POSES_PER_S:,.0f} poses/s",
            "–" if not col else f"{col['poses_per_s']:,.0f} poses/s{also}",
            None if best is None else best >= BATCH_POSES_PER_S,
        )
    )
    return rows


def run_http(
    models: Path,
    edits: Edits,
    *,
    solve_set: str,
    concurrency: Sequence[int] = (1, 8, 64),
    requests: int = 3000,
    seconds: float = 15.0,
    batch_size: int = 1024,
    batches: int = 12,
    batch_seconds: float = 30.0,
    warmup: int = 200,
    paced: int = 400,
    log: Path | None = None,
) -> Json:
    """The whole HTTP measurement; returns a JSON-able dict. /v1/solve at concurrency 1
    and the columnar batch are measured three times: with the models' defaults, with
    ``options.passes = 1`` (``solve_passes1``, ``batch_columnar_passes1``) and with
    ``options.mirror = false`` (``solve_no_mirror``, ``batch_columnar_no_mirror``).
    ``solve_paced``: ``paced`` requests at concurrency 1 sent at a drag's pace
    (:data:`DRAG_GAP_S` apart), where the server idles between requests as it does under
    an editor, and its caches go cold (docs/speed.md)."""
    items = bodies(edits)
    single = [json.dumps(b).encode() for b in items]
    single1 = [json.dumps(b).encode() for b in bodies(edits, passes=1)]
    single_m = [json.dumps(b).encode() for b in bodies(edits, mirror=False)]
    n_batch = max(1, min(4, -(-batch_size * 2 // len(items))))
    rows = [
        [(s * batch_size + j) % len(items) for j in range(batch_size)]
        for s in range(max(2, n_batch))
    ]
    batch_payloads = [json.dumps({"items": [items[i] for i in r]}).encode() for r in rows]
    columns, columns1, columns_m = (
        [json.dumps(columnar_body(edits, r, passes=p, mirror=m)).encode() for r in rows]
        for p, m in ((None, None), (1, None), (None, False))
    )
    packed = [json.dumps(columnar_body(edits, r, packed=True)).encode() for r in rows]
    out: Json = {
        "solve_set": solve_set,
        "client": f"raw HTTP/1.1: concurrency 1 on a blocking socket, more on {client_loop()}",
        "limits": f"≤ {requests} requests or ≤ {seconds:g} s per concurrency level; "
        f"batch ≤ {batches} batches or ≤ {batch_seconds:g} s",
        "solve": [],
    }
    with serve(models, log=log) as server:
        out["server"] = server.command
        rss: Json = {"after_start": rss_kb(server.pid)}
        load(f"{server.url}/v1/solve", single, 4, warmup, 30.0)
        load(f"{server.url}/v1/solve", single1, 1, warmup, 30.0)
        load(f"{server.url}/v1/solve", single_m, 1, warmup, 30.0)
        load(f"{server.url}/v1/solve/batch", batch_payloads[:1], 1, 1, 60.0)
        load(f"{server.url}/v1/solve/batch", columns[:1], 1, 2, 60.0)
        load(f"{server.url}/v1/solve/batch", columns1[:1], 1, 2, 60.0)
        load(f"{server.url}/v1/solve/batch", columns_m[:1], 1, 2, 60.0)
        load(f"{server.url}/v1/solve/batch", packed[:1], 1, 2, 60.0)
        rss["after_warm_up"] = rss_kb(server.pid)
        for c in concurrency:
            out["solve"].append(load(f"{server.url}/v1/solve", single, c, requests, seconds))
        out["solve_passes1"] = load(f"{server.url}/v1/solve", single1, 1, requests, seconds)
        out["solve_no_mirror"] = load(f"{server.url}/v1/solve", single_m, 1, requests, seconds)
        out["solve_paced"] = _load_one(
            f"{server.url}/v1/solve", single, paced, paced * DRAG_GAP_S + seconds, DRAG_GAP_S
        )
        b = load(f"{server.url}/v1/solve/batch", batch_payloads, 1, batches, batch_seconds)
        out["batch"] = _batch_row(b, batch_size, len(batch_payloads[0]))
        col = load(f"{server.url}/v1/solve/batch", columns, 1, 4 * batches, batch_seconds)
        out["batch_columnar"] = _batch_row(col, batch_size, len(columns[0]))
        col1 = load(f"{server.url}/v1/solve/batch", columns1, 1, 4 * batches, batch_seconds)
        out["batch_columnar_passes1"] = _batch_row(col1, batch_size, len(columns1[0]))
        col_m = load(f"{server.url}/v1/solve/batch", columns_m, 1, 4 * batches, batch_seconds)
        out["batch_columnar_no_mirror"] = _batch_row(col_m, batch_size, len(columns_m[0]))
        col_p = load(f"{server.url}/v1/solve/batch", packed, 1, 4 * batches, batch_seconds)
        out["batch_columnar_packed"] = _batch_row(col_p, batch_size, len(packed[0]))
        rss["after_load"] = rss_kb(server.pid)
        out["rss_kb"] = rss
    return out
