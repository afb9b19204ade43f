"""Tests marked ``alone`` run while no other test of the session runs (a plugin of
``tests/conftest.py``).

A few tests bound wall time: a hang or a quadratic read is caught as "took < 2 s", a
deadline as "ended within 0.9-3 s". ``make test`` runs the suite in two pytest-xdist
workers, so such a test could run beside the container image's build or a browser test,
on a host of two cores, and take several times its own time. Under xdist every test now
holds a lock file the workers share: the others share it, an ``alone`` test holds it by
itself (``fcntl.flock``), so it waits for the test running on the other worker to end,
and that worker waits for it. A turnstile lock, taken before the shared one, keeps the
other worker's stream of short tests from starving it. An ``alone`` test waits at most
:data:`PATIENCE` for the other worker's test to end (the container image's build takes
1-2 min), then runs beside it all the same: the lock is a best effort, not a guarantee,
and it cost the suite a minute of waits when it waited for ever. Without xdist the fixture
does nothing (one test runs at a time anyway).

The lock is held from before a test's own fixtures are set up (autouse, function scope)
until they are torn down; a module's or session's fixtures (a server started once for a
file) stay up beside it, idle.
"""

from __future__ import annotations

import fcntl
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import pytest


def lock_paths(worker_temp: Path) -> tuple[Path, Path]:
    """The run's turnstile and its shared lock, beside the workers' temp folders (xdist
    gives each worker ``<the run's basetemp>/popen-gwN``; pytest prunes old basetemps)."""
    return worker_temp.parent / "alone.turn", worker_temp.parent / "alone.lock"


#: Seconds an ``alone`` test waits for the lock before it runs without it.
PATIENCE = 20.0


def _flocked(stack: ExitStack, path: Path, how: int, patience: float | None = None) -> None:
    """``path`` locked (``fcntl.LOCK_SH`` or ``LOCK_EX``) until ``stack`` closes; with
    ``patience``, tried until that many seconds have passed, then left unlocked."""
    f = stack.enter_context(path.open("a"))
    if patience is None:
        fcntl.flock(f, how)
    else:
        until = time.monotonic() + patience
        while True:
            try:
                fcntl.flock(f, how | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() >= until:
                    return  # (run beside the other test)
                time.sleep(0.05)
    stack.callback(fcntl.flock, f, fcntl.LOCK_UN)


@contextmanager
def held(turn: Path, lock: Path, alone: bool, patience: float = PATIENCE) -> Iterator[None]:
    """``lock`` held shared, or by this holder alone (``alone``: for at most ``patience``
    seconds of waiting, then not at all), taken through the turnstile ``turn``: a holder
    waiting to be alone waits at the turnstile's far side, so holders who come after it
    wait behind it, not beside the holders it waits for."""
    with ExitStack() as stack:
        with ExitStack() as turnstile:
            _flocked(turnstile, turn, fcntl.LOCK_EX)
            if alone:
                _flocked(stack, lock, fcntl.LOCK_EX, patience)
            else:
                _flocked(stack, lock, fcntl.LOCK_SH)
        yield


@pytest.fixture(autouse=True)
def _alone_or_shared(
    request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory
) -> Iterator[None]:
    if not hasattr(request.config, "workerinput"):  # not an xdist worker
        yield
        return
    alone = request.node.get_closest_marker("alone") is not None
    with held(*lock_paths(tmp_path_factory.getbasetemp()), alone):
        yield
