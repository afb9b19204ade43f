"""The lock that runs a test marked ``alone`` while no other test runs (``tests/alone.py``):
two holders at once, in threads of this process (``flock`` locks belong to each open file,
so two opens conflict as two processes' would)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from tests.alone import held, lock_paths

WAIT = 0.3  # s: long enough for a holder that could enter to have entered


def _enter(paths: tuple[Path, Path], alone: bool, inside: list[str], name: str,
           leave: threading.Event, patience: float = 30.0) -> threading.Thread:  # fmt: skip
    def run() -> None:
        with held(*paths, alone, patience):
            inside.append(name)
            leave.wait(10)
        inside.remove(name)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t


def test_shared_holders_run_together_and_one_alone_waits_for_them(tmp_path: Path) -> None:
    paths = lock_paths(tmp_path / "popen-gw0")
    inside: list[str] = []
    leave_a, leave_b, leave_c = threading.Event(), threading.Event(), threading.Event()
    a = _enter(paths, False, inside, "a", leave_a)
    b = _enter(paths, False, inside, "b", leave_b)
    time.sleep(WAIT)
    assert sorted(inside) == ["a", "b"]  # shared: both at once
    c = _enter(paths, True, inside, "c", leave_c)
    time.sleep(WAIT)
    assert "c" not in inside  # alone: waits while any other holds the lock
    leave_a.set()
    a.join(5)
    time.sleep(WAIT)
    assert inside == ["b"]
    leave_b.set()
    b.join(5)
    time.sleep(WAIT)
    assert inside == ["c"]
    leave_c.set()
    c.join(5)
    assert inside == [] and not c.is_alive()


def test_a_holder_that_comes_after_one_waiting_alone_waits_behind_it(tmp_path: Path) -> None:
    """The turnstile: without it, shared holders coming one after another could keep the
    one that waits alone waiting for ever."""
    paths = lock_paths(tmp_path / "popen-gw0")
    inside: list[str] = []
    leave = {n: threading.Event() for n in "abc"}
    a = _enter(paths, False, inside, "a", leave["a"])
    time.sleep(WAIT)
    b = _enter(paths, True, inside, "b", leave["b"])  # waits for a
    time.sleep(WAIT)
    c = _enter(paths, False, inside, "c", leave["c"])  # shared, but comes after b
    time.sleep(WAIT)
    assert inside == ["a"]  # c did not slip in beside a
    leave["a"].set()
    time.sleep(WAIT)
    assert inside == ["b"]
    leave["b"].set()
    time.sleep(WAIT)
    assert inside == ["c"]
    leave["c"].set()
    for t in (a, b, c):
        t.join(5)
    assert inside == []


def test_one_waiting_alone_runs_beside_the_others_once_its_patience_is_spent(
    tmp_path: Path,
) -> None:
    paths = lock_paths(tmp_path / "popen-gw0")
    inside: list[str] = []
    leave = {n: threading.Event() for n in "abc"}
    a = _enter(paths, False, inside, "a", leave["a"])
    time.sleep(WAIT)
    b = _enter(paths, True, inside, "b", leave["b"], patience=1.0)
    time.sleep(WAIT)
    assert inside == ["a"]  # within its patience: waits
    time.sleep(1.0)
    assert sorted(inside) == ["a", "b"]  # spent: runs beside a
    c = _enter(paths, False, inside, "c", leave["c"])  # not held back by b, which holds nothing
    time.sleep(WAIT)
    assert sorted(inside) == ["a", "b", "c"]
    for n, t in zip("abc", (a, b, c), strict=True):
        leave[n].set()
        t.join(5)
    assert inside == []
