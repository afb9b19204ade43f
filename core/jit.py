"""The numeric JIT the compiled kernels are built with (numba), configured in one place.

* ``cache=True``: compiled machine code is kept on disk, so a second start loads it in
  about a second instead of compiling (20-40 s cold). Numba writes it next to the
  sources when that folder is writable; otherwise (a read-only container) into
  ``$NUMBA_CACHE_DIR``, set here to a per-user folder under the temp dir when the
  environment does not set it, first filled from ``$MARIONETTE_NUMBA_SEED`` if given
  (the image compiles the kernels at build time into such a seed).
* no ``fastmath``, no ``parallel``: IEEE arithmetic in source order (no reassociation,
  no fused multiply-add contraction), one thread, so a kernel's answer for an item is
  bit-identical from run to run and whatever batch the item is in.
* ``nogil=True``: a kernel releases the GIL, so solves in worker threads overlap.

:func:`jit` is typed so that strict mypy checks the callers against the Python
signature of each kernel.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast


def _cache_dir() -> None:
    """Point numba's cache at a writable folder when the package folder is not one, and
    seed it from ``$MARIONETTE_NUMBA_SEED`` (a cache compiled at image build time, read
    only) when it is empty: a read-only container then starts without compiling."""
    seed = os.environ.get("MARIONETTE_NUMBA_SEED")
    target = os.environ.get("NUMBA_CACHE_DIR")
    if not target:
        here = Path(__file__).resolve().parent
        if os.access(here, os.W_OK) and not seed:
            return
        uid = os.getuid() if hasattr(os, "getuid") else 0
        target = str(Path(tempfile.gettempdir()) / f"marionette-numba-{uid}")
        os.environ["NUMBA_CACHE_DIR"] = target
    if seed and Path(seed).is_dir() and not Path(target).exists():
        with contextlib.suppress(OSError):  # no seed then: the kernels compile at warm-up
            shutil.copytree(seed, target)


_cache_dir()

import numba  # noqa: E402  (after the cache folder is chosen: numba reads it on import)

F = TypeVar("F", bound=Callable[..., Any])


def jit(fn: F) -> F:
    """``numba.njit`` with the project's fixed options (see the module docstring)."""
    return cast(F, numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")(fn))
