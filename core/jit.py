"""The numeric JIT the compiled kernels are built with (numba), configured in one place.

* ``cache=True``: compiled machine code is kept on disk, so a second start loads it in
  about a second instead of compiling (20-40 s cold). It goes under ``core/__pycache__``
  when that folder is writable; otherwise (a read-only container) under
  ``$NUMBA_CACHE_DIR``, or a per-user folder under the temp dir when the environment
  does not set it, first filled from ``$MARIONETTE_NUMBA_SEED`` if given (the image
  compiles the kernels at build time into such a seed).
* Each of those holds one subfolder per :func:`fingerprint` of the package's sources.
  Numba checks a cached kernel against its own file's mtime only, but the kernels bake
  in constants read from other modules (the skeleton, the rest pose, the chains of
  :mod:`core.ends`): an edit there must not leave a stale kernel in use.
* no ``fastmath``, no ``parallel``: IEEE arithmetic in source order (no reassociation,
  no fused multiply-add contraction), one thread, so a kernel's answer for an item is
  bit-identical from run to run and whatever batch the item is in.
* ``nogil=True``: a kernel releases the GIL, so solves in worker threads overlap.

:func:`jit` is typed so that strict mypy checks the callers against the Python
signature of each kernel.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

from core import CacheDirError


def fingerprint(folder: Path) -> str:
    """A short hash of the contents of every ``*.py`` in ``folder`` (names and bytes)."""
    digest = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def _cache_dir() -> None:
    """Point numba's cache at this package's sources' :func:`fingerprint` folder: under
    ``core/__pycache__`` when writable, else ``$NUMBA_CACHE_DIR`` or a per-user temp
    folder, seeded from ``$MARIONETTE_NUMBA_SEED`` (a cache compiled at image build time,
    read only) when that is empty: a read-only container then starts without compiling."""
    here = Path(__file__).resolve().parent
    mark = fingerprint(here)
    seed = os.environ.get("MARIONETTE_NUMBA_SEED")
    base = os.environ.get("NUMBA_CACHE_DIR")
    if base and Path(base).name == mark:  # set so by this function in a parent process
        base = str(Path(base).parent)
    if not base:
        if os.access(here, os.W_OK) and not seed:
            base = str(here / "__pycache__" / "numba")
        else:
            uid = os.getuid() if hasattr(os, "getuid") else 0
            try:
                temp = tempfile.gettempdir()
            except FileNotFoundError:  # a read-only root without its writable /tmp
                raise CacheDirError(
                    "no writable folder for the compiled kernels' cache: mount a writable "
                    "/tmp (an emptyDir, a tmpfs) or set NUMBA_CACHE_DIR to one"
                ) from None
            base = str(Path(temp) / f"marionette-numba-{uid}")
    os.environ["NUMBA_CACHE_DIR"] = str(Path(base) / mark)  # numba reads it on import
    if seed and Path(seed).is_dir() and not Path(base).exists():
        with contextlib.suppress(OSError):  # no seed then: the kernels compile at warm-up
            shutil.copytree(seed, base)


_cache_dir()

import numba  # noqa: E402  (after the cache folder is chosen: numba reads it on import)

F = TypeVar("F", bound=Callable[..., Any])


def jit(fn: F) -> F:
    """``numba.njit`` with the project's fixed options (see the module docstring)."""
    return cast(F, numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")(fn))
