"""Fault tests on a real uvicorn on 127.0.0.1 (issue 12): heavy and abandoned batches,
big bodies against liveness, SIGTERM under load, a corrupt model, a truncated manifest.
Each prints the figure it measures (``pytest -s`` shows them)."""

from __future__ import annotations

import http.client
import json
import shutil
import signal
import socket
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.rest import rest_pose
from core.skeleton import JOINT_NAMES
from tests.service.server import heavy_batch, liveness_probed, serve

pytestmark = pytest.mark.slow
PROBLEM = "application/problem+json"


def assert_problem(status: int, headers: dict[str, str], data: bytes, *codes: int) -> Any:
    assert status in codes, (status, data[:300])
    assert headers["content-type"].startswith(PROBLEM), headers
    return json.loads(data)


def test_heavy_batches_are_bounded_by_the_deadline(models_dir: Path, tmp_path: Path) -> None:
    body = heavy_batch()
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS="2") as s:
        results: list[tuple[float, int]] = []
        answers: list[tuple[int, dict[str, str], bytes]] = []

        def one() -> None:
            t = time.perf_counter()
            answers.append(s.request("POST", "/v1/solve/batch", body))
            results.append((time.perf_counter() - t, answers[-1][0]))

        threads = [threading.Thread(target=one) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        worst = max(w for w, _ in results)
        print(f"\n4 heavy batches at once ({len(body) / 1e6:.1f} MB each): {results}")
        assert len(answers) == 4, results
        for status, headers, data in answers:
            if status != 200:  # a 504 says how far it got; Retry-After only if it waited
                problem = assert_problem(status, headers, data, 504)
                if "before reading the body" not in problem["detail"]:  # (items unknown)
                    assert 0 <= problem["done"] < problem["total"] == 1024, problem
                own = "of its own compute" in problem["detail"]
                assert headers.get("retry-after") == (None if own else "1"), (headers, problem)
        assert worst < 2 + 1.5, results  # the deadline plus one chunk and the answer
        assert s.request("GET", "/v2/health/live")[0] == 200


def _slow_lone_edit(seed: int = 1) -> bytes:
    """A lone soft edit slow to solve (on the event loop: no pins, soft reach): 18 targets,
    4 passes, the turn search and the mirror image (20-60 ms on this 2-core host)."""
    rng = np.random.default_rng(seed)
    pose = rest_pose()
    joints = [JOINT_NAMES[i] for i in rng.permutation(len(JOINT_NAMES))[:18]]
    return json.dumps({
        "pose": dict(zip(JOINT_NAMES, pose.round(4).tolist(), strict=True)),
        "targets": [{"joint": j, "position": (pose[JOINT_NAMES.index(j)]
                                              + rng.normal(0, 0.3, 3)).round(4).tolist()}
                    for j in joints],
        "options": {"passes": 4, "turn_search": True, "mirror": True, "tolerance": 1e-6},
    }).encode()  # fmt: skip


def test_lone_soft_edits_on_a_busy_loop_end_at_their_deadline(
    models_dir: Path, tmp_path: Path
) -> None:
    """64 clients of one slow lone soft edit. It was solved on the event loop, one after
    another, and never looked at its deadline (an audit: 256 answers, all 200, the last
    4.75 s into a 2 s deadline), its clock started only when its turn came (the
    middleware's), not when its head was read. Now a turn search or extra passes go to a
    worker on a compute token within the deadline (``service.routes.solve.inline``), and
    an inline solve looks at its deadline first: one whose deadline passed is a 504,
    unsolved; those solved are answered within the deadline and one solve (X-Total-Time:
    the server's clock; a 30 ms deadline, for a few 504s whatever the host's pace)."""
    body, deadline = _slow_lone_edit(), 0.03
    answers: list[tuple[int, float, bytes]] = []
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS=str(deadline)) as s:

        def client() -> None:
            conn = http.client.HTTPConnection("127.0.0.1", s.port, timeout=60)
            try:
                for _ in range(3):
                    conn.request("POST", "/v1/solve", body, {"content-type": "application/json"})
                    resp = conn.getresponse()
                    data = resp.read()
                    took = float(resp.getheader("x-total-time", "nan").removesuffix("ms")) / 1e3
                    assert resp.status == 200 or resp.getheader("retry-after") == "1"
                    answers.append((resp.status, took, data))
            finally:
                conn.close()

        threads = [threading.Thread(target=client) for _ in range(64)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        metrics = s.request("GET", "/metrics")[2].decode()
    late = [json.loads(data)["detail"] for status, _, data in answers if status == 504]
    served = [took for status, took, _ in answers if status == 200]
    print(f"\n192 slow lone edits from 64 clients, {deadline} s deadline: {len(served)} 200s "
          f"(X-Total-Time max {max(served, default=0):.3f} s), {len(late)} 504s")  # fmt: skip
    assert len(answers) == 192 and len(late) + len(served) == 192, answers[:3]
    # (64-103 of 192 here; 0 with the clock started in the middleware, 0 without the check)
    assert len(late) >= 10, f"{len(late)} requests found their deadline passed"
    assert all(f"the {deadline:g} s deadline (" in d for d in late), late[:3]
    assert 'reason="deadline-exceeded",route="/v1/solve"' in metrics
    assert max(served, default=0) < deadline + 1.0, sorted(served)[-5:]


def _stall(port: int, declared: int) -> socket.socket:
    """A connection that sends a request's head and the first byte of its body, then
    nothing more (a stalled or very slow upload)."""
    sock = socket.create_connection(("127.0.0.1", port))
    sock.sendall(
        b"POST /v1/solve HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
        + f"content-length: {declared}\r\n\r\n{{".encode()
    )
    return sock


@pytest.mark.alone
def test_stalled_uploads_end_at_the_deadline_and_free_their_slots(
    models_dir: Path, tmp_path: Path
) -> None:
    """A body that does not arrive is a 408 at the deadline and its connection closed; as
    many stalled uploads as the worker admits turn others away only until then (before:
    for as long as their clients kept the connections open)."""
    solve = (Path(__file__).parents[2] / "docs" / "examples" / "solve.json").read_bytes()
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS="1", POSE_MAX_CONCURRENCY="8") as s:
        sock = _stall(s.port, 100_000)
        sock.settimeout(10)
        t = time.perf_counter()
        answer = b""
        while chunk := sock.recv(65536):  # read to the close
            answer += chunk
        took = time.perf_counter() - t
        head, _, data = answer.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 408"), head
        assert b"connection: close" in head.lower() and PROBLEM.encode() in head
        problem = json.loads(data)
        assert problem["type"].endswith("/request-timeout"), problem
        assert "1 s deadline" in problem["detail"] and "1 of 100000 bytes" in problem["detail"]
        assert 0.9 < took < 3.0, took
        sock.close()
        print(f"\nstalled upload: 408 after {took:.2f} s")
        stalled = [_stall(s.port, 1000) for _ in range(8)]  # every admission slot
        time.sleep(0.3)
        assert s.request("POST", "/v1/solve", solve)[0] == 429
        time.sleep(1.5)  # past their deadline
        status, _, data = s.request("POST", "/v1/solve", solve)
        assert status == 200, data[:300]
        for c in stalled:
            c.close()


def _abandon(port: int, body: bytes, after: float) -> None:
    with socket.create_connection(("127.0.0.1", port)) as sock:
        head = (
            f"POST /v1/solve/batch HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
            f"content-length: {len(body)}\r\n\r\n"
        )
        sock.sendall(head.encode() + body)
        time.sleep(after)


@pytest.mark.alone
def test_abandoned_batches_stop_and_say_so(models_dir: Path, tmp_path: Path) -> None:
    body = heavy_batch()
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS="120") as s:
        threads = [threading.Thread(target=_abandon, args=(s.port, body, 0.5)) for _ in range(6)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        left = time.perf_counter()
        gone: list[dict[str, Any]] = []
        while len(gone) < 6 and time.perf_counter() - left < 30:  # each stops at a chunk
            time.sleep(0.1)
            gone = [x for x in s.log_lines() if x.get("path") == "/v1/solve/batch"]
        stopped = time.perf_counter() - left
        c0, t0 = s.cpu_seconds(), time.perf_counter()
        time.sleep(3.0)
        cores = (s.cpu_seconds() - c0) / (time.perf_counter() - t0)
        print(
            f"\n6 abandoned heavy batches: all stopped {stopped:.1f} s after the clients "
            f"left; CPU over the next 3 s: {cores:.3f} cores"
        )
        assert cores < 0.1
        assert len(gone) == 6 and all(x["status"] == 499 for x in gone), gone
        assert all(x["outcome"] == "client_disconnected" for x in gone)


def test_a_body_cut_short_by_its_client_is_never_solved(models_dir: Path, tmp_path: Path) -> None:
    """A client that closes before its body is whole is a 499 in the log, never solved or
    read as broken JSON, end to end on a real server: a whole JSON body 10 bytes short of
    its Content-Length, and a chunked one whose last chunk never comes. (Whether the code
    before saw these depended on timing: the gate test below holds the rule itself.)"""
    solve = (Path(__file__).parents[2] / "docs" / "examples" / "solve.json").read_bytes()
    head = "POST /v1/solve HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
    with serve(models_dir, tmp_path) as s:
        with socket.create_connection(("127.0.0.1", s.port)) as sock:
            sock.sendall(f"{head}content-length: {len(solve) + 10}\r\n\r\n".encode() + solve)
            time.sleep(0.3)
        with socket.create_connection(("127.0.0.1", s.port)) as sock:
            chunk = f"{len(solve):x}\r\n".encode() + solve + b"\r\n"  # no last chunk
            sock.sendall(f"{head}transfer-encoding: chunked\r\n\r\n".encode() + chunk)
            time.sleep(0.3)
        lines: list[dict[str, Any]] = []
        t = time.perf_counter()
        while len(lines) < 2 and time.perf_counter() - t < 10:
            time.sleep(0.1)
            lines = [x for x in s.log_lines() if x.get("path") == "/v1/solve"]
        metrics = s.request("GET", "/metrics")[2].decode()
        assert s.request("POST", "/v1/solve", solve)[0] == 200  # the worker goes on
    assert [(x["status"], x["outcome"]) for x in lines] == [(499, "client_disconnected")] * 2
    # neither was read as a body: no solve, no broken JSON; each refused as the client's
    assert "pose_solves_total{" not in metrics and "malformed-body" not in metrics, metrics
    assert 'pose_rejections_total{reason="client-disconnected",route="/v1/solve"} 2.0' in metrics


@pytest.mark.parametrize("framing", ["content-length", "chunked"])
def test_the_gate_never_hands_on_a_body_its_client_left(framing: str) -> None:
    """The gate itself, as the server runs it, fed what uvicorn gives an app when the client
    closes mid-body (a first part, then ``http.disconnect``): it answered the app with the
    part as if whole (a chunked body whose first chunk was a whole JSON object was solved;
    whether the end-to-end test above sees it depends on timing). Now a 499, nothing on."""
    import asyncio

    from service.middleware.gate import Gate
    from service.middleware.types import REASON
    from service.settings import Settings

    solve = (Path(__file__).parents[2] / "docs" / "examples" / "solve.json").read_bytes()
    framing_header = (
        (b"content-length", str(len(solve) + 10).encode())
        if framing == "content-length"
        else (b"transfer-encoding", b"chunked")
    )
    scope: dict[str, Any] = {
        "type": "http", "method": "POST", "path": "/v1/solve", "query_string": b"",
        "headers": [(b"content-type", b"application/json"), framing_header],
    }  # fmt: skip
    inbox = [
        {"type": "http.request", "body": solve, "more_body": True},
        {"type": "http.disconnect"},
    ]
    sent: list[dict[str, Any]] = []
    reached: list[bytes] = []

    async def receive() -> dict[str, Any]:
        return inbox.pop(0) if inbox else {"type": "http.disconnect"}

    async def send(message: dict[str, Any]) -> None:
        sent.append(message)

    async def app(scope: Any, receive: Any, send: Any) -> None:
        reached.append((await receive())["body"])

    gate = Gate(app, Settings())
    asyncio.run(gate(scope, receive, send))  # type: ignore[arg-type]
    assert reached == [], "the body was handed on"
    assert sent[0]["status"] == 499 and scope[REASON] == "client-disconnected"
    assert gate.active == 0 and gate.held == 0  # its admission slot and bytes given back


def test_liveness_answers_while_big_bodies_are_parsed(models_dir: Path, tmp_path: Path) -> None:
    body = json.dumps(json.loads(heavy_batch(seed=7)), indent=1).encode()
    with serve(models_dir, tmp_path, POSE_DEADLINE_SECONDS="1") as s:

        def flood() -> None:
            s.request("POST", "/v1/solve/batch", body)

        floods = [threading.Thread(target=flood) for _ in range(16)]
        with liveness_probed(s, every=0.05, timeout=10) as latencies:
            for t in floods:
                t.start()
            for t in floods:
                t.join()
        rss = s.rss_mib()
        print(
            f"\nliveness during 16 x {len(body) / 2**20:.1f} MiB bodies: max "
            f"{max(latencies) * 1000:.0f} ms over {len(latencies)} probes; RSS {rss:.0f} MiB"
        )
        assert max(latencies) < 1.0


@pytest.mark.alone
def test_huge_bvh_hierarchies_are_refused_fast_and_leave_no_memory(
    models_dir: Path, tmp_path: Path
) -> None:
    """An audit's finding (2026-12-06): five 8.3 MB BVH bodies of 4.15 M hierarchy words
    (an 8 MB request body holds that many) took a worker from 329 to 2,452 MiB, each
    answered after 2.2-3.9 s: the reader split the whole hierarchy before any limit, and a
    reference cycle kept the words. Now each is refused at once and the worker's memory
    stays where it was (a few MiB of allocator slack a request)."""
    bvh = "HIERARCHY\nROOT " + "a " * 4_150_000 + "\n{\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n"
    body = json.dumps({"bvh": bvh, "frame": 0}).encode()
    with serve(models_dir, tmp_path) as s:
        before, took, rss, details = s.rss_mib(), [], [], []
        for _ in range(5):
            start = time.perf_counter()
            status, headers, data = s.request("POST", "/v1/bvh/inspect", body)
            took.append(time.perf_counter() - start)
            rss.append(s.rss_mib())
            details.append(assert_problem(status, headers, data, 422)["detail"])
        print(f"\n5 x 8.3 MB hierarchies: {max(took):.2f} s at most, RSS {before:.0f} -> "
              + " -> ".join(f"{r:.0f}" for r in rss) + " MiB")  # fmt: skip
        assert rss[-1] - before < 100, (before, rss)  # (was +420 MiB a request)
        assert max(took) < 1.5, took  # (was 2.2-3.9 s)
        for detail in details:
            assert detail.startswith("bvh: line 2: a joint name of more than 200"), detail


def test_sigterm_under_load_answers_problems_not_text(models_dir: Path, tmp_path: Path) -> None:
    # 4096 exact-reach items take ~4 s to solve here (1024 took ~1 s once the engine was
    # compiled, so a batch could finish before the signal): all three are still in flight
    body = heavy_batch(n=4096, seed=3)
    env: dict[str, str] = {
        "POSE_DEADLINE_SECONDS": "120",
        "POSE_SHUTDOWN_GRACE_SECONDS": "1",
        "POSE_MAX_BATCH_ITEMS": "4096",
        "POSE_MAX_BODY_BYTES": str(64 << 20),
    }
    with serve(models_dir, tmp_path, True, **env) as s:
        answers: list[tuple[int, dict[str, str], bytes]] = []

        def one() -> None:
            answers.append(s.request("POST", "/v1/solve/batch", body))

        threads = [threading.Thread(target=one) for _ in range(3)]
        for t in threads:
            t.start()
        time.sleep(1.5)
        s.proc.send_signal(signal.SIGTERM)
        for t in threads:
            t.join(30)
        s.proc.wait(30)
        assert len(answers) == 3
        for status, headers, data in answers:
            problem = assert_problem(status, headers, data, 503)
            assert problem["type"].endswith("/shutting-down") and headers["retry-after"]
        lines = [x for x in s.log_lines() if x.get("path") == "/v1/solve/batch"]
        assert len(lines) == 3 and all(x["status"] == 503 for x in lines), lines
        assert "Traceback" not in s.log.read_text()


def test_sigterm_while_the_models_load_exits_at_once(models_dir: Path, tmp_path: Path) -> None:
    """An ops audit's find: a stop during the load (here a cold numba cache, as on a node
    whose CPU the image's seed was not compiled for: ~20-50 s of compiling) waited for the
    whole load, past the grace period, and the container was killed (137)."""
    env = {"NUMBA_CACHE_DIR": str(tmp_path / "cold-cache"), "POSE_SHUTDOWN_GRACE_SECONDS": "1"}
    with serve(models_dir, tmp_path, False, **env) as s:
        status, _, body = s.request("GET", "/v2/health/ready")
        assert status == 503 and b"loading" in body, body  # the kernels compile
        t0 = time.monotonic()
        s.proc.send_signal(signal.SIGTERM)
        s.proc.wait(30)
        took = time.monotonic() - t0
        # (-15: uvicorn ends by re-raising the signal it handled; PID 1 in a container
        # exits 0 instead)
        assert s.proc.returncode in (0, -signal.SIGTERM) and took < 5, (s.proc.returncode, took)
        log = s.log.read_text()
        assert "Application shutdown complete." in log and "Traceback" not in log


@pytest.mark.parametrize("fault", ["corrupt-model", "truncated-manifest"])
def test_broken_models_are_not_ready_with_file_names(
    models_dir: Path, tmp_path: Path, fault: str
) -> None:
    broken = tmp_path / "private" / "models"
    shutil.copytree(models_dir, broken)
    if fault == "corrupt-model":
        (broken / "encoder.onnx").write_bytes(b"\x00" * 100)
        name = "encoder.onnx"
    else:
        text = (broken / "manifest.json").read_text()
        (broken / "manifest.json").write_text(text[: len(text) // 2])
        name = "manifest.json"
    with serve(broken, tmp_path, ready=False) as s:
        # live is up before the load fails: on a loaded host (pytest-xdist's other worker,
        # other suites) the first look at ready found it still loading
        status, _, data = s.request("GET", "/v2/health/ready")
        until = time.monotonic() + 60
        while b"loading models" in data and time.monotonic() < until:
            time.sleep(0.1)
            status, _, data = s.request("GET", "/v2/health/ready")
        assert status == 503 and name in data.decode()
        answer = s.request("POST", "/v1/solve", b"{}")
        assert answer[0] in (422, 503)
        for d in (data, answer[2]):
            assert str(tmp_path) not in d.decode()
        assert s.request("GET", "/v2/health/live")[0] == 200


def _big_bvh_solve(frames: int = 15_500) -> bytes:
    """The docs' BVH edit with its motion repeated to ``frames`` frames (7.6 MB): an answer
    of the same size, more than a loopback socket takes at once (~4 MB)."""
    example = json.loads((Path(__file__).parents[2] / "docs/examples/bvh_solve.json").read_text())
    head, motion = example["bvh"].split("MOTION\n")
    lines = motion.strip().split("\n")
    rows = (lines[2:] * (frames // len(lines[2:]) + 1))[:frames]
    example["bvh"] = f"{head}MOTION\nFrames: {frames}\n{lines[1]}\n" + "\n".join(rows) + "\n"
    return json.dumps(example).encode()


def _unread(port: int, body: bytes, window: int | None = 4096) -> socket.socket:
    """A client that sends a BVH edit and does not read its answer (yet); ``window``: its
    socket's receive buffer (None: the system's)."""
    sock = socket.socket()
    if window is not None:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, window)
    sock.connect(("127.0.0.1", port))
    sock.sendall(
        b"POST /v1/bvh/solve HTTP/1.1\r\nhost: x\r\ncontent-type: application/json\r\n"
        + f"content-length: {len(body)}\r\n\r\n".encode()
        + body
    )
    return sock


def _drain(sock: socket.socket) -> bytes:
    """What the server sends until it closes the connection or the answer is whole."""
    sock.settimeout(10)
    out = b""
    try:
        while chunk := sock.recv(1 << 20):
            out += chunk
            head, _, data = out.partition(b"\r\n\r\n")
            length = [h for h in head.lower().split(b"\r\n") if h.startswith(b"content-length")]
            if length and len(data) >= int(length[0].split(b":")[1]):
                break
    except ConnectionResetError:
        pass
    return out


def test_answers_nobody_reads_are_bounded_per_worker(models_dir: Path, tmp_path: Path) -> None:
    """The answers a worker holds for clients that do not take them stay within
    ``POSE_MAX_UNSENT_BYTES``: past it the longest-waiting connections are closed and their
    answers dropped, oldest first (before: held for as long as the clients kept their
    connections; twelve 7.6 MB BVH answers, +125 MB). The one left within the bound gets
    its whole answer when it reads at last.

    The server runs with the image's ``MALLOC_ARENA_MAX=2``, and the same eight edits,
    read, come first: the growth measured is what the unread answers hold more than what
    the allocator keeps of the solves. Without that warm-up a CI run measured +45 MiB
    (bound kept), where this host measured +12; with it, three runs here +7, +8, +21 MiB,
    and with no bound in effect (``POSE_MAX_UNSENT_BYTES`` 1 GiB) +59, +59, +73."""
    body = _big_bvh_solve()
    env = {"POSE_MAX_UNSENT_BYTES": str(8 << 20), "MALLOC_ARENA_MAX": "2"}
    with serve(models_dir, tmp_path, **env) as s:
        status, _, whole = s.request("POST", "/v1/bvh/solve", body)
        assert status == 200 and len(whole) > 7_000_000
        for _ in range(8):  # the same work, its answers read: the allocator's high water
            assert _drain(_unread(s.port, body, window=None)).startswith(b"HTTP/1.1 200")
        before = s.rss_mib()
        socks = []
        for _ in range(8):  # one after another: each once the one before is answered
            socks.append(_unread(s.port, body))
            socks[-1].settimeout(30)
            socks[-1].recv(1, socket.MSG_PEEK)
        slow: list[dict[str, Any]] = []
        for _ in range(50):  # the last answer may still be on its way on a slow host
            slow = [e for e in s.log_lines() if e.get("event") == "slow-reader"]
            if len(slow) >= 7:
                break
            time.sleep(0.2)
        after = s.rss_mib()
        got = [_drain(c) for c in socks[:-1]]  # the last one still holds its answer
        print(f"\n8 unread 7.6 MB answers: RSS {before:.0f} -> {after:.0f} MiB, {len(slow)} "
              f"dropped, each after {min(map(len, got)) / 1e6:.1f} MB")  # fmt: skip
        assert all(g.startswith(b"HTTP/1.1 200") and len(g) < len(whole) for g in got), [
            g[:12] + b" %d" % len(g) for g in got
        ]
        assert len(slow) == 7 and all(e["others_unsent"] <= 8 << 20 for e in slow), slow
        assert after - before < 40, (before, after)  # not 8 x the ~5 MB unsent
        assert "pose_slow_readers_total 7.0" in s.request("GET", "/metrics")[2].decode()
        last = _drain(socks[-1])  # read at last: the whole answer
        head, _, data = last.partition(b"\r\n\r\n")
        assert head.startswith(b"HTTP/1.1 200") and json.loads(data) == json.loads(whole)
        for c in socks:
            c.close()
