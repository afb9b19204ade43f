"""Prometheus collectors of one app instance (own registry: apps don't collide).

Every label has a bounded set of values: routes are route templates (or ``unmatched``),
solver sequences are a trained key, ``composed``, ``none`` or ``fabrik``."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import CounterMetricFamily
from prometheus_client.registry import Collector

from service.transport import PacedHTTPProtocol


class _SlowReaders(Collector):
    """Connections closed on a client that did not take its answer (``service.transport``,
    counted per process, as the protocol has no app to count in)."""

    def collect(self) -> list[CounterMetricFamily]:
        help_ = "Connections closed on a client that did not take its answer"
        dropped = PacedHTTPProtocol.dropped
        return [CounterMetricFamily("pose_slow_readers", help_, value=dropped)]


#: Steps of a solver path that are not trained solvers: the FABRIK polish and fallback,
#: the pins' polish, the turn search's turn or fitted start (``service.engine``,
#: ``service.pins``, ``service.turns``).
_STEPS = ("fabrik", "pin-polish", "turn ", "fit ")


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
            buckets=(0.0005, 0.001, 0.002, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0, 5.0),
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
            "Items per /v1/solve/batch request",
            buckets=(1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 4096),
            registry=self.registry,
        )
        self.registry.register(_SlowReaders())

    def solved(self, method: str, solvers: list[str], n: int = 1) -> None:
        """Count ``n`` solves under a bounded label (never an open-ended combination)."""
        neural = [s for s in solvers if not s.startswith(_STEPS)]
        if method == "fabrik":
            label = "fabrik"
        elif not neural:
            label = "none"
        else:
            label = neural[0] if len(neural) == 1 else "composed"
        self.solves.labels(method, label).inc(n)

    def solved_paths(
        self, method: str, paths: Sequence[Sequence[str]], path_of: npt.NDArray[np.int64]
    ) -> None:
        """Count a batch's solves by solver path (``BatchAnswer.paths`` / ``path_of``)."""
        for path, n in zip(paths, np.bincount(path_of, minlength=len(paths)).tolist(),
                           strict=True):  # fmt: skip
            self.solved(method, list(path), n)
