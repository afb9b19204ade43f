"""Prometheus collectors of one app instance (own registry: apps don't collide), and the
worker processes' sum when there are several (:func:`shared`).

Every label has a bounded set of values: routes are route templates (or ``unmatched``),
solver sequences are a trained key, ``composed``, ``none`` or ``fabrik``."""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from prometheus_client import (
    GC_COLLECTOR,
    PLATFORM_COLLECTOR,
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    ProcessCollector,
    generate_latest,
    multiprocess,
)

from service.problems import trained_solvers
from service.settings import SHARED_DIR
from service.transport import CONNECTIONS_CLOSED, SLOW_READERS

#: Solver paths whose counter child :meth:`Metrics.solved` keeps.
HELD_PATHS = 256
#: ``pose_request_seconds``'s buckets: from 0.5 ms to ``POSE_DEADLINE_SECONDS``'s most (600
#: s); they stopped at 5 s, so every request past it, a 504 at a deadline of 30 s, was +Inf.
LATENCY_BUCKETS = (
    0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0, 2.5, 5.0,
    10.0, 30.0, 60.0, 120.0, 300.0, 600.0,
)  # fmt: skip


def _this_process(registry: CollectorRegistry) -> None:
    """The process's own series in ``registry``: ``process_*`` (resident and virtual
    memory, CPU seconds, open and most file descriptors, start time: Linux's /proc),
    ``python_info`` and ``python_gc_*`` (prometheus_client's collectors; the app's own
    registry had none of them, an ops audit)."""
    ProcessCollector(registry=registry)
    registry.register(PLATFORM_COLLECTOR)
    registry.register(GC_COLLECTOR)


@contextlib.contextmanager
def shared(workers: int) -> Iterator[None]:
    """``pose-service --workers N`` (N > 1): the workers' metrics in one fresh folder,
    removed at the end, so that ``/metrics`` answers the service's counts whichever worker
    takes the scrape (each worker kept its own before: a scrape read one worker's). An
    operator's own ``PROMETHEUS_MULTIPROC_DIR`` is used as it is (emptied by them before a
    start, as prometheus_client asks)."""
    if workers <= 1 or os.environ.get(SHARED_DIR):
        yield
        return
    folder = tempfile.mkdtemp(prefix="marionette-metrics-")
    os.environ[SHARED_DIR] = folder  # the workers, spawned afresh, inherit it
    try:
        yield
    finally:
        os.environ.pop(SHARED_DIR, None)
        shutil.rmtree(folder, ignore_errors=True)


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.requests = Counter(
            "pose_requests_total", "HTTP requests", ["route", "status"], registry=self.registry
        )
        self.latency = Histogram(
            "pose_request_seconds",
            "HTTP request latency",
            ["route"],
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.in_flight = Gauge(
            "pose_requests_in_flight",
            "HTTP requests under way (read, worked on or answered), by this worker or, "
            "with several, all of them",
            registry=self.registry,
            multiprocess_mode="livesum",  # (the live workers' sum; a dead one's left out)
        )
        self.preflights = Counter(
            "pose_cors_preflights_total",
            "CORS preflights answered by the CORS layer (outside the other metrics), by "
            "result: allowed (200) or refused (400, cors-rejected)",
            ["result"],
            registry=self.registry,
        )
        self.rejections = Counter(
            "pose_rejections_total",
            "Requests refused before or instead of any work, by reason",
            ["route", "reason"],
            registry=self.registry,
        )
        self.solves = Counter(
            "pose_solves_total",
            "Solves by method and solver sequence (a trained key, composed, none, fabrik)",
            ["method", "solvers"],
            registry=self.registry,
        )
        self.batch = Histogram(
            "pose_batch_items",
            "Items per batch request (/v1/solve/batch items, /v1/bvh/solve/batch edits)",
            buckets=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 4096),
            registry=self.registry,
        )
        self.registry.register(SLOW_READERS)
        self.registry.register(CONNECTIONS_CLOSED)
        _this_process(self.registry)
        self._solved: dict[tuple[str, ...], Any] = {}  # (method, *path) -> the child

    def exposition(self) -> bytes:
        """The text ``/metrics`` answers: this app's collectors, or with several worker
        processes (:data:`SHARED_DIR` set) the sum of every worker's."""
        folder = os.environ.get(SHARED_DIR)
        if not folder:
            return generate_latest(self.registry)
        registry = CollectorRegistry()
        multiprocess.MultiProcessCollector(registry, path=folder)  # type: ignore[no-untyped-call]
        # (the workers' files hold no process series: these are the worker answering)
        _this_process(registry)
        return generate_latest(registry)

    def solved(self, method: str, solvers: list[str], n: int = 1) -> None:
        """Count ``n`` solves under a bounded label (never an open-ended combination).
        The counter's child is kept by method and solver path (``labels`` looks up and
        locks each time); at most :data:`HELD_PATHS` paths are kept (a path may name a
        turn's degrees)."""
        key = (method, *solvers)
        child = self._solved.get(key)
        if child is None:
            neural = trained_solvers(solvers)
            if method == "fabrik":
                label = "fabrik"
            elif not neural:
                label = "none"
            else:
                label = neural[0] if len(neural) == 1 else "composed"
            child = self.solves.labels(method, label)
            if len(self._solved) >= HELD_PATHS:
                self._solved.clear()
            self._solved[key] = child
        child.inc(n)

    def solved_paths(
        self, method: str, paths: Sequence[Sequence[str]], path_of: npt.NDArray[np.int64]
    ) -> None:
        """Count a batch's solves by solver path (``BatchAnswer.paths`` / ``path_of``)."""
        for path, n in zip(paths, np.bincount(path_of, minlength=len(paths)).tolist(),
                           strict=True):  # fmt: skip
            self.solved(method, list(path), n)
