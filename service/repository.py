"""The model repository: loads, verifies and warms up the models, and holds readiness
(as in kserve, readiness belongs to the repository, not to the transport)."""

from __future__ import annotations

import contextlib
import json
import logging
import time

from core.manifest import (
    ManifestError,
    SkeletonSpec,
    edited_version,
    load_manifest,
    written_version,
)
from service.engine import Engine
from service.errors import ModelsFailed, NotReady
from service.settings import Settings

log = logging.getLogger("service")


def _redact(reason: str, settings: Settings) -> str:
    """A failure reason that names files, never where they live on the server."""
    for path in sorted({str(settings.models_dir.resolve()), str(settings.models_dir)}, key=len):
        reason = reason.replace(path.rstrip("/") + "/", "").replace(path, "<models>")
    return reason


class ModelRepository:
    """The loaded :class:`Engine` once it is ready, else why not."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.engine: Engine | None = None
        self.skeleton: SkeletonSpec | None = None
        self.reason: str = "loading models"
        #: the load failed: for good, the service never loads again (:meth:`not_ready`)
        self.failed = False

    @property
    def ready(self) -> bool:
        return self.engine is not None

    def not_ready(self) -> NotReady:
        """Why not ready: still loading (503, ``Retry-After``), or failed for good (503
        ``models-failed``, no ``Retry-After``: an operator must act)."""
        if self.failed:
            return ModelsFailed(
                f"models failed to load: {self.reason} (the service does not retry: fix the "
                "models, then restart it)"
            )
        return NotReady(f"models not ready: {self.reason}")

    def ready_engine(self) -> Engine:
        if self.engine is None:
            raise self.not_ready()
        return self.engine

    def skeleton_spec(self) -> SkeletonSpec:
        """The skeleton, served as soon as the manifest parses (before verification)."""
        spec = self.engine.manifest.skeleton if self.engine else self.skeleton
        if spec is None:
            raise self.not_ready()
        return spec

    def load(self) -> None:
        """Load, verify and warm up the models; record why not when anything fails."""
        s = self.settings
        t0 = time.perf_counter()
        log.info(
            json.dumps(
                {"event": "models_loading", "models_dir": str(s.models_dir),
                 "detail": "loading, verifying and warming up the models; the first start "
                 "after an install or a code change also compiles the kernels (~1 min)"}
            )
        )  # fmt: skip
        with contextlib.suppress(ManifestError):
            self.skeleton = load_manifest(s.models_dir, verify=False).skeleton
        try:
            engine = Engine(
                s.models_dir,
                threads=s.ort_threads,
                composition_passes=s.composition_passes,
                composition=s.composition,
                composition_projections=s.composition_projections,
                fabrik_max_iterations=s.fabrik_max_iterations,
                serving={} if s.solve_mirror is None else {"solve_mirror": s.solve_mirror},
            )
            engine.warmup()
        except Exception as exc:  # any failure means "not ready", with the reason logged
            self.reason, self.failed = _redact(str(exc), s), True
            log.error(
                json.dumps(
                    {"event": "models_not_ready", "models_dir": str(s.models_dir),
                     "reason": str(exc)}
                )
            )  # fmt: skip
            return
        self.engine = engine
        self.reason = ""
        if (content := edited_version(engine.manifest)) is not None:
            log.warning(
                json.dumps(
                    {"event": "manifest_edited", "version": engine.version,
                     "content_version": content,
                     "written_version": written_version(engine.manifest),
                     "detail": "manifest.json was edited by hand (its content is not what "
                     "its content_sha256, or its version, says was written): its answers are "
                     "not the ones its written version names, so it is served under the "
                     "version of its content; set serving settings with `pose-trainer "
                     "serving`, which gives the models a version of their own"}
                )
            )  # fmt: skip
        inert, why = engine.inert_settings()
        if inert:  # set, but nothing here for them to change
            log.warning(
                json.dumps(
                    {"event": "settings_ignored", "version": engine.version,
                     "settings": [f"POSE_{n.upper()}" for n in inert], "reason": why}
                )
            )  # fmt: skip
        log.info(
            json.dumps(
                {"event": "models_ready", "version": engine.version,
                 "models_dir": str(s.models_dir), "s": round(time.perf_counter() - t0, 3)}
            )
        )  # fmt: skip
