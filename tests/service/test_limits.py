"""The work budget's parts (service.limits): a batch's priced parts run in waves on the
compute tokens free at the time, with the same answers, byte for byte, whatever the width."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import anyio
import numpy as np
import pytest

from service.limits import ComputeLimiter, _wave
from tests.conftest import PosePairs, make_client
from tests.service.test_columnar import columns


def test_a_wave_runs_its_parts_at_once_and_answers_in_order() -> None:
    both = threading.Barrier(2, timeout=20)  # broken unless two parts run at the same time

    def fn(part: slice) -> tuple[int, int]:
        both.wait()
        return part.start, threading.get_ident()

    got = anyio.run(_wave, fn, [slice(0, 3), slice(3, 5)], ComputeLimiter(2))
    assert [start for start, _ in got] == [0, 3]
    assert got[0][1] != got[1][1]


def test_a_wave_raises_the_first_error_in_part_order_after_every_part_ended() -> None:
    ended: list[int] = []

    def fn(part: slice) -> int:
        ended.append(part.start)
        if part.start > 0:
            raise ValueError(f"part {part.start}")
        return part.start

    with pytest.raises(ValueError, match="part 1"):
        anyio.run(_wave, fn, [slice(0, 1), slice(1, 2), slice(2, 3)], ComputeLimiter(3))
    assert sorted(ended) == [0, 1, 2]


def test_a_wave_takes_only_free_tokens_and_never_waits_holding_one() -> None:
    limiter = ComputeLimiter(3)
    running, most = [0], [0]
    lock = threading.Lock()

    def fn(part: slice) -> int:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        threading.Event().wait(0.05)
        with lock:
            running[0] -= 1
        return part.start

    async def beside_another_request() -> list[int]:
        limiter.acquire_on_behalf_of_nowait(object())  # another request's compute
        return await _wave(fn, [slice(i, i + 1) for i in range(5)], limiter)

    got = anyio.run(beside_another_request)
    assert got == [0, 1, 2, 3, 4]
    assert most[0] == 2  # the two free tokens, not three
    assert limiter.borrowed_tokens == 1  # its own given back


@pytest.mark.parametrize("route", ["columnar", "items"])
def test_the_answer_is_the_same_on_one_compute_thread_or_two(
    models_dir: Path, real_poses: PosePairs, route: str
) -> None:
    body: dict[str, Any] = columns(real_poses, 700)  # 1,400 units: 6 parts, 3 waves of 2
    if route == "items":
        from tests.service.test_columnar import items

        body = {"items": items(body)}
    answers = []
    for threads in (1, 2):  # (a deadline a loaded host cannot miss: 700 items on one thread)
        with make_client(models_dir, compute_threads=threads, deadline_seconds=120.0) as c:
            r = c.post("/v1/solve/batch", json=body)
            assert r.status_code == 200, r.text
            answers.append(r.content)
    assert answers[0] == answers[1]


@pytest.mark.parametrize("route", ["columnar", "items"])
def test_a_batch_whose_items_are_all_done_is_answered_with_no_compute_thread_free(
    models_dir: Path, real_poses: PosePairs, route: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every item solved, then the one compute thread taken by another request until
    after this one's deadline: the answer is written anyway, the same bytes as on a calm
    server. Before, writing the answer waited for a compute token within the deadline, and
    under overload a batch whose items were all done was a 504 "before writing the
    answer", its work thrown away (an overload audit; docs/limits.md)."""
    body: dict[str, Any] = columns(real_poses, 300)  # > 32 items: answered in a worker thread
    if route == "items":
        from tests.service.test_columnar import items

        body = {"items": items(body)}
    deadline = 1.0
    with make_client(models_dir, deadline_seconds=deadline, compute_threads=1) as c:
        calm = c.post("/v1/solve/batch", json=body)
        assert calm.status_code == 200, calm.text
        limiter, metrics = c.app.state.compute_limiter, c.app.state.pose.metrics
        holder, timers = object(), []
        batch = metrics.batch

        class TakenOnceDone:
            """The batch metric, observed on the event loop once every item is solved:
            the moment the other request takes the token and keeps it past the deadline."""

            def observe(self, n: int) -> None:
                batch.observe(n)
                limiter.acquire_on_behalf_of_nowait(holder)  # the last wave gave it back
                release = (limiter.release_on_behalf_of, holder)
                timers.append(threading.Timer(deadline + 1.0, c.portal.call, release))
                timers[-1].start()

        monkeypatch.setattr(metrics, "batch", TakenOnceDone())
        try:
            resp = c.post("/v1/solve/batch", json=body)
            held = [t.is_alive() for t in timers]
        finally:
            for t in timers:
                t.join()
        assert held == [True]  # answered while the token was still taken
        assert resp.status_code == 200, resp.text
        assert resp.content == calm.content


def test_soft_unpinned_edits_run_on_the_loop_and_the_rest_in_a_worker(
    client: Any, real_poses: PosePairs, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A single edit in neural soft reach without pins, no more passes than served, one
    solver and no turn search is answered on the event loop's thread, a 5-target edit the
    gate keeps from searching too (one solver of its own); pins, exact reach, FABRIK, extra
    passes, a turn search and composed solvers run in a worker thread, so the loop stays
    free of their work (``service.routes.solve.inline``). Composed solvers ran on the loop
    once: an API audit (2026-12-08) held it 8-26 ms a lone 15-target soft edit."""
    from service.engine import Engine
    from service.problems import SolveResult
    from tests.service.test_api import solve_body

    where: list[int] = []  # the thread of each solve
    solve, solve_lone, searching = Engine.solve, Engine.solve_lone, Engine.solve_searching

    def spy(self: Engine, problems: Any) -> Any:
        where.append(threading.get_ident())
        return solve(self, problems)

    def spy_lone(self: Engine, p: Any) -> Any:  # a solve where it answers (not a search)
        n = len(where)
        result = solve_lone(self, p)
        if isinstance(result, SolveResult) and len(where) == n:
            where.append(threading.get_ident())
        return result

    def spy_searching(self: Engine, p: Any, searches: Any) -> Any:  # a search's solve
        where.append(threading.get_ident())
        return searching(self, p, searches)

    monkeypatch.setattr(Engine, "solve", spy)
    monkeypatch.setattr(Engine, "solve_lone", spy_lone)
    monkeypatch.setattr(Engine, "solve_searching", spy_searching)
    looks: list[int] = []  # the items each solve makes of its problem
    items_of = Engine._items_of

    def spy_items(self: Engine, p: Any) -> Any:
        looks.append(1)
        return items_of(self, p)

    monkeypatch.setattr(Engine, "_items_of", spy_items)
    five = ["head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]
    wrists = solve_body(real_poses, 0, ["left_wrist", "right_wrist"])
    pinned = {**wrists, "pins": ["left_ankle"]}
    still = solve_body(real_poses, 0, five)  # its targets 1 cm from its joints: no search
    for t in still["targets"]:
        t["position"] = [v + 0.01 for v in still["pose"][t["joint"]]]
    turned = solve_body(real_poses, 0, five, lambda p: p @ np.diag([-1.0, 1.0, -1.0]))
    turned["pose"] = still["pose"]  # its goal turned half round: it searches
    bodies = {
        "light": [
            wrists,
            solve_body(real_poses, 1, ["left_elbow"]),
            still,
        ],
        "worker": [
            solve_body(real_poses, 0, ["left_elbow", "right_knee"]),  # two solvers composed
            pinned,
            solve_body(real_poses, 0, ["left_wrist"], reach="exact"),
            solve_body(real_poses, 0, ["left_wrist"], method="fabrik"),
            solve_body(real_poses, 0, ["left_wrist"], passes=3),
            turned,
        ],
    }
    threads: dict[str, list[int]] = {}
    for kind, group in bodies.items():
        threads[kind] = []
        for body in group:
            where.clear()
            looks.clear()
            r = client.post("/v1/solve", json=body)
            assert r.status_code == 200, r.text
            assert len(where) == 1
            threads[kind].append(where[0])
            if body is turned:  # its items made once, for the look and the search alike
                assert r.json()["solvers"] and len(looks) == 1
    loop = threads["light"][0]
    assert set(threads["light"]) == {loop}
    assert loop not in threads["worker"]


def test_compute_tokens_go_to_the_oldest_request_first() -> None:
    limiter = ComputeLimiter(1)
    order: list[str] = []

    async def ask(name: str, age: float) -> None:
        borrower = object()
        await limiter.acquire_on_behalf_of(borrower, age)
        order.append(name)
        await anyio.sleep(0.01)
        limiter.release_on_behalf_of(borrower)

    async def main() -> None:
        holder = object()
        await limiter.acquire_on_behalf_of(holder)
        async with anyio.create_task_group() as tg:
            for name, age in (("late", 3.0), ("first", 1.0), ("middle", 2.0)):
                tg.start_soon(ask, name, age)  # asks in this order, arrived in another
            await anyio.sleep(0.05)
            assert limiter.borrowed_tokens == 1
            with pytest.raises(anyio.WouldBlock):  # a waiter comes before a newcomer
                limiter.acquire_on_behalf_of_nowait(object())
            limiter.release_on_behalf_of(holder)

    anyio.run(main)
    assert order == ["first", "middle", "late"]
    assert limiter.borrowed_tokens == 0


def test_a_cancelled_waiter_gives_up_its_place_or_the_token_it_was_handed() -> None:
    limiter = ComputeLimiter(1)
    got: list[str] = []

    async def main() -> None:
        holder = object()
        await limiter.acquire_on_behalf_of(holder)
        scopes = {name: anyio.CancelScope() for name in ("a", "b", "c")}

        async def ask(name: str, age: float) -> None:
            borrower = object()
            with scopes[name]:
                await limiter.acquire_on_behalf_of(borrower, age)
                got.append(name)
                limiter.release_on_behalf_of(borrower)

        async with anyio.create_task_group() as tg:
            for name, age in (("a", 1.0), ("b", 2.0), ("c", 3.0)):
                tg.start_soon(ask, name, age)
            await anyio.sleep(0.05)
            scopes["b"].cancel()  # waiting: leaves the queue
            await anyio.sleep(0.01)
            scopes["a"].cancel()  # cancelled, but before it runs ...
            limiter.release_on_behalf_of(holder)  # ... handed the token: passed on to "c"

    anyio.run(main)
    assert got == ["c"]
    assert limiter.borrowed_tokens == 0


@pytest.mark.alone
def test_under_overload_the_first_requests_finish_first(
    tmp_path: Path, real_poses: PosePairs
) -> None:
    """Sixteen big batches at once on a real server: the first answers come while the
    others wait, instead of all of them advancing a stage each in turn and ending together
    (before the oldest-first tokens: 16 such batches within a 2 s deadline were 16 504s)."""
    import json
    import time

    from tests.service.server import REPO, serve

    body = json.dumps(columns(real_poses, 1024)).encode()
    done: list[float] = []
    with serve(REPO / "models", tmp_path, POSE_DEADLINE_SECONDS="120") as server:
        assert server.request("POST", "/v1/solve/batch", body)[0] == 200  # warm

        def one() -> None:
            status = server.request("POST", "/v1/solve/batch", body, timeout=120)[0]
            assert status == 200
            done.append(time.perf_counter())

        t0 = time.perf_counter()
        threads = [threading.Thread(target=one) for _ in range(16)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    took = sorted(d - t0 for d in done)
    assert len(took) == 16
    assert took[1] < 0.5 * took[-1], took  # tokens shared in turn: all within ~10 % (2.52-2.76 s)
