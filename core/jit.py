"""The numeric JIT the compiled kernels are built with (numba), configured in one place.

* ``cache=True``: compiled machine code is kept on disk, so a second start loads it in
  about a second instead of compiling (about a minute at 1 CPU). It goes under
  ``core/__pycache__`` when that folder is writable; otherwise (a read-only container)
  under ``$NUMBA_CACHE_DIR``, or a per-user folder under the temp dir when the
  environment does not set it.
* ``$MARIONETTE_NUMBA_SEED`` (set in the image) names a cache compiled at build time:
  its folder for these sources is copied into the cache folder whenever that holds no
  kernels yet, whatever folder it is (a fresh ``/tmp``, an emptyDir mounted as
  ``$NUMBA_CACHE_DIR``). A seed compiled from other sources, or from sources at another
  path (numba names its folders after the sources' path), is not copied, and a
  ``kernel_seed_unused`` warning says so: that start compiles.
* A cache folder that cannot be written is refused (:class:`core.CacheDirError`, which
  ``pose-service`` turns into a ``start_refused`` line): numba would otherwise keep
  nothing, or fall back to ``core/__pycache__`` without the fingerprint below, without
  a word, and every start would compile.
* Each of those holds one subfolder per :func:`fingerprint` of the package's sources.
  A start marks its own as used (its mtime) and removes all but the ``KEEP_OTHERS`` most
  recently used of the others (16-hex-digit names only), so a cache kept across edits or
  image upgrades (a developer's ``core/__pycache__``, a persistent ``$NUMBA_CACHE_DIR``)
  does not grow by a folder of kernels per version for ever.
  Numba checks a cached kernel against its own file's contents only (a sha256 of the
  source, numba 0.68; its folder is named after the source's path), but the kernels bake
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

import hashlib
import json
import logging
import os
import secrets
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar, cast

from core import CacheDirError

_log = logging.getLogger(__name__)

#: Fingerprint folders besides this start's that a cache keeps (the most recently used):
#: a process still running an older version recompiles into its own if it must.
KEEP_OTHERS = 3


def fingerprint(folder: Path) -> str:
    """A short hash of the contents of every ``*.py`` in ``folder`` (names and bytes)."""
    digest = hashlib.sha256()
    for path in sorted(folder.glob("*.py")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def numba_subfolder(source_dir: str) -> str:
    """The folder numba keeps the kernels of the sources in ``source_dir`` in, inside its
    cache folder: the folder's name and a hash of its absolute path (numba's
    ``_CacheLocator.get_suitable_cache_subpath``). A seed is of use only to sources at the
    path it was compiled from."""
    path = os.path.abspath(source_dir)
    return f"{os.path.basename(path)}_{hashlib.sha1(path.encode()).hexdigest()}"


def _writable(folder: Path) -> None:
    """Make ``folder`` if missing and a file in it, as numba does before it uses a cache
    folder (on an ``OSError`` numba silently looks elsewhere or keeps nothing)."""
    folder.mkdir(parents=True, exist_ok=True)
    tempfile.TemporaryFile(dir=folder).close()


def _empty(folder: Path) -> bool:
    try:
        return next(folder.iterdir(), None) is None
    except FileNotFoundError:
        return True


def _copy(source: Path, target: Path) -> None:
    """The files of ``source`` into the existing folder ``target``: contents only, so the
    copies get this process's modes, writable, not the seed's (read-only files, root's)."""
    for parent, _, names in os.walk(source):
        out = target / Path(parent).relative_to(source)
        out.mkdir(exist_ok=True)
        for name in names:
            shutil.copyfile(Path(parent, name), out / name)


def _seed(source: Path, folder: Path) -> bool:
    """Fill the missing or empty ``folder`` with a copy of ``source``: copied into a new
    sibling, then renamed (onto an empty folder too), so that another worker starting at
    the same moment sees the whole seed or none of it. False when another process filled
    ``folder`` first (its copy is used, this one removed)."""
    temp = folder.with_name(f".{folder.name}.seed-{os.getpid()}-{secrets.token_hex(4)}")
    temp.mkdir()
    try:
        _copy(source, temp)
        try:
            os.rename(temp, folder)
        except OSError:
            if _empty(folder):
                raise
            return False  # another worker's copy (or its compiled kernels) came first
        return True
    finally:
        shutil.rmtree(temp, ignore_errors=True)  # gone after a rename, else a leftover


def _unused(seed: Path, folder: Path, why: str) -> None:
    _log.warning(
        json.dumps({
            "event": "kernel_seed_unused",
            "seed": str(seed),
            "folder": str(folder),
            "detail": f"{why}: the kernels compile at this start (about a minute at 1 CPU)",
        })
    )  # fmt: skip


def _use_seed(seed: Path, folder: Path, subfolder: str) -> None:
    """Copy the seed's kernels for these sources into ``folder`` when it holds none (a new
    cache folder, an emptyDir, a tmpfs, whatever folder it is in); say so when the seed is
    of no use."""
    if not _empty(folder):  # kept by an earlier start, or another worker's
        return
    source = seed / folder.name
    if not seed.is_dir():
        return _unused(seed, folder, "the seed is no folder")
    if not source.is_dir():
        return _unused(
            seed, folder, f"the seed holds no kernels for these sources (their fingerprint, "
            f"{folder.name}, is not in it: it was compiled from other code)"
        )  # fmt: skip
    if not (source / subfolder).is_dir():
        return _unused(
            seed, folder, f"the seed was compiled from sources at another path (numba's "
            f"folder for this one, {subfolder}, is not in it)"
        )  # fmt: skip
    try:
        copied = _seed(source, folder)
    except OSError as exc:
        return _unused(seed, folder, f"the seed could not be copied ({exc})")
    event = "kernel_seed_copied" if copied else "kernel_seed_raced"  # (info: not shown at import)
    _log.info(json.dumps({"event": event, "seed": str(seed), "folder": str(folder)}))


def _prune(folder: Path) -> None:
    """Mark ``folder`` used now and remove its fingerprint siblings but the ``KEEP_OTHERS``
    most recently used. Best effort: a folder another process removes first, or one that
    cannot be removed, is left to the next start."""
    try:
        os.utime(folder)
        others = [
            (p.stat().st_mtime, p)
            for p in folder.parent.iterdir()
            if p != folder and p.is_dir() and len(p.name) == 16
            and all(c in "0123456789abcdef" for c in p.name)
        ]  # fmt: skip
    except OSError:
        return
    for _, old in sorted(others, reverse=True)[KEEP_OTHERS:]:
        shutil.rmtree(old, ignore_errors=True)


def _refusal(folder: Path, given: str | None, exc: OSError) -> CacheDirError:
    fix = (
        "set NUMBA_CACHE_DIR to a writable folder (an emptyDir, a tmpfs) or unset it"
        if given
        else "mount a writable /tmp (an emptyDir, a tmpfs) or set NUMBA_CACHE_DIR to one"
    )
    return CacheDirError(
        f"no writable folder for the compiled kernels' cache: {folder} cannot be written "
        f"({exc.strerror or exc}), so numba would keep no kernels and every start would "
        f"compile them (about a minute at 1 CPU): {fix}"
    )


def _cache_dir() -> None:
    """Point numba's cache at this package's sources' :func:`fingerprint` folder: under
    ``core/__pycache__`` when writable, else ``$NUMBA_CACHE_DIR`` or a per-user temp
    folder; filled from ``$MARIONETTE_NUMBA_SEED`` (a cache compiled at image build time,
    read only) when it holds nothing yet, so a read-only container starts without
    compiling. A folder that cannot be written is refused (:class:`CacheDirError`)."""
    here = Path(__file__).resolve().parent
    mark = fingerprint(here)
    seed = os.environ.get("MARIONETTE_NUMBA_SEED")
    base = given = os.environ.get("NUMBA_CACHE_DIR")
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
    folder = Path(base) / mark
    os.environ["NUMBA_CACHE_DIR"] = str(folder)  # numba reads it on import
    subfolder = numba_subfolder(os.path.dirname(os.path.abspath(__file__)))
    try:
        _writable(folder)
        if seed:
            _use_seed(Path(seed), folder, subfolder)
        _writable(folder / subfolder)  # numba's own (a seed's copy: made by this process)
    except OSError as exc:
        raise _refusal(folder, given, exc) from None
    _prune(folder)


_cache_dir()

import numba  # noqa: E402  (after the cache folder is chosen: numba reads it on import)

F = TypeVar("F", bound=Callable[..., Any])


def jit(fn: F) -> F:
    """``numba.njit`` with the project's fixed options (see the module docstring)."""
    return cast(F, numba.njit(cache=True, nogil=True, fastmath=False, error_model="numpy")(fn))
