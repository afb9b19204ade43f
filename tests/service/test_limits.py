"""The work budget's parts (service.limits): a batch's priced parts run in waves on the
compute tokens free at the time, with the same answers, byte for byte, whatever the width."""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import anyio
import pytest

from service.limits import _wave
from tests.conftest import PosePairs, make_client
from tests.service.test_columnar import columns


def test_a_wave_runs_its_parts_at_once_and_answers_in_order() -> None:
    both = threading.Barrier(2, timeout=20)  # broken unless two parts run at the same time

    def fn(part: slice) -> tuple[int, int]:
        both.wait()
        return part.start, threading.get_ident()

    got = anyio.run(_wave, fn, [slice(0, 3), slice(3, 5)], anyio.CapacityLimiter(2))
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
        anyio.run(_wave, fn, [slice(0, 1), slice(1, 2), slice(2, 3)], anyio.CapacityLimiter(3))
    assert sorted(ended) == [0, 1, 2]


def test_a_wave_takes_only_free_tokens_and_never_waits_holding_one() -> None:
    limiter = anyio.CapacityLimiter(3)
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
    for threads in (1, 2):
        with make_client(models_dir, compute_threads=threads) as c:
            r = c.post("/v1/solve/batch", json=body)
            assert r.status_code == 200, r.text
            answers.append(r.content)
    assert answers[0] == answers[1]


def test_soft_unpinned_edits_run_on_the_loop_and_the_rest_in_a_worker(
    client: Any, real_poses: PosePairs, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A single edit in neural soft reach without pins is answered on the event loop's
    thread, the turn search and composed solvers too (in a worker they share the GIL with
    the loop and took longer: docs/service.md); pins, exact reach and FABRIK run in a
    worker thread, so the loop stays free of their FABRIK iterations."""
    from service.engine import Engine
    from tests.service.test_api import solve_body

    where: list[int] = []
    solve = Engine.solve

    def spy(self: Engine, problems: Any) -> Any:
        where.append(threading.get_ident())
        return solve(self, problems)

    monkeypatch.setattr(Engine, "solve", spy)
    five = ["head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]
    wrists = solve_body(real_poses, 0, ["left_wrist", "right_wrist"])
    pinned = {**wrists, "pins": ["left_ankle"]}
    bodies = {
        "light": [
            wrists,
            solve_body(real_poses, 1, ["left_elbow"]),
            solve_body(real_poses, 0, five),  # the turn search
            solve_body(real_poses, 0, ["left_elbow", "right_knee"]),  # two solvers composed
        ],
        "worker": [
            pinned,
            solve_body(real_poses, 0, ["left_wrist"], reach="exact"),
            solve_body(real_poses, 0, ["left_wrist"], method="fabrik"),
        ],
    }
    threads: dict[str, list[int]] = {}
    for kind, group in bodies.items():
        threads[kind] = []
        for body in group:
            where.clear()
            r = client.post("/v1/solve", json=body)
            assert r.status_code == 200, r.text
            assert len(where) == 1
            threads[kind].append(where[0])
    loop = threads["light"][0]
    assert set(threads["light"]) == {loop}
    assert loop not in threads["worker"]
