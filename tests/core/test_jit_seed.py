"""The image's kernel seed (``MARIONETTE_NUMBA_SEED``) and the cache folder's checks, run
for real: a small package with a copy of ``core/jit.py`` and one kernel, compiled into a
seed by numba in one process and loaded from the copy in another (an ops audit,
2026-12-06: with ``NUMBA_CACHE_DIR`` set to an existing folder, ``/tmp`` or an emptyDir,
the seed was never copied and every pod start compiled for 47-71 s, without a word; an
unwritable ``NUMBA_CACHE_DIR`` compiled at every start, without a word)."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import core.jit
from core.jit import fingerprint, numba_subfolder
from tests.conftest import REPO_ROOT

CORE = Path(core.jit.__file__).resolve().parent

# The kernel's answer, then how often numba loaded it from the cache and compiled it.
KERNEL = """from pkg.consts import K
from pkg.jit import jit


@jit
def f() -> int:
    return K


print(f(), sum(f.stats.cache_hits.values()), sum(f.stats.cache_misses.values()))
"""


def _package(src: Path, k: int = 1) -> Path:
    pkg = src / "pkg"
    pkg.mkdir(parents=True)
    shutil.copy(CORE / "jit.py", pkg / "jit.py")
    (pkg / "__init__.py").write_text("")
    (pkg / "kern.py").write_text(KERNEL)
    (pkg / "consts.py").write_text(f"K = {k}\n")
    return pkg


def _env(src: Path, cache: Path | str, seed: Path | None = None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "MARIONETTE_"))}
    env |= {"PYTHONPATH": f"{src}{os.pathsep}{REPO_ROOT}", "NUMBA_CACHE_DIR": str(cache)}
    if seed is not None:
        env["MARIONETTE_NUMBA_SEED"] = str(seed)
    return env


def _run(src: Path, cache: Path | str, seed: Path | None = None) -> tuple[str, list[str]]:
    """``import pkg.kern``: its line (answer, cache hits, compiles) and its stderr lines.
    No bytecode written (-B): ``consts.py`` rewritten as ``K = 2`` in the second it was
    first imported, at its size, passed for the cached ``K = 1``'s source (CPython checks
    a .pyc by the source's mtime in whole seconds and its size), and the kernel answered 1
    (CI, once ``make test`` wrote bytecode)."""
    out = subprocess.run(
        [sys.executable, "-P", "-B", "-c", "import pkg.kern"],
        env=_env(src, cache, seed), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip(), out.stderr.splitlines()


def _seed(tmp_path: Path, src: Path) -> Path:
    """A seed made as docker/Dockerfile makes the image's: ``NUMBA_CACHE_DIR`` at it."""
    seed = tmp_path / "seed"
    assert _run(src, seed)[0] == "1 0 1"  # compiled
    return seed


@pytest.fixture(scope="module")
def seeded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """``(src, pkg, seed)``: the package and its seed, made once for the tests that leave
    the package as it is (each made its own: a numba start and a compile, ~2 s a test)."""
    root = tmp_path_factory.mktemp("seeded")
    src = root / "src"
    pkg = _package(src)
    return src, pkg, _seed(root, src)


@pytest.mark.parametrize("base", ["existing", "with-other-files", "missing"])
def test_the_seed_fills_the_cache_folder_whatever_folder_it_is_in(
    seeded: tuple[Path, Path, Path], tmp_path: Path, base: str
) -> None:
    """``NUMBA_CACHE_DIR=/tmp`` or an emptyDir: the folder exists (and may hold other
    files); the seed's kernels for these sources are copied into ``<base>/<fingerprint>``
    and numba loads them, none compiled (the seed was copied only when ``<base>`` did not
    exist: the first two cases compiled)."""
    src, pkg, seed = seeded
    cache = tmp_path / "cache"
    if base != "missing":
        cache.mkdir()
    if base == "with-other-files":
        (cache / "other.txt").write_text("not ours")
        (cache / "0123456789abcdef").mkdir()  # another version's kernels
    line, err = _run(src, cache, seed)
    assert line == "1 1 0", err  # loaded from the copy, not compiled
    assert err == []  # nothing to warn of
    mark = fingerprint(pkg)
    (sub,) = [p.name for p in (cache / mark).iterdir()]
    assert sub == numba_subfolder(str(pkg))  # numba's own naming, as core.jit predicts it
    assert list((cache / mark / sub).glob("*.nbi"))
    assert not [p for p in cache.iterdir() if ".seed-" in p.name]  # no copy left behind
    assert _run(src, cache, seed)[0] == "1 1 0"  # the next start: the same folder


def test_a_start_keeps_its_own_and_the_three_most_recently_used_versions_kernels(
    tmp_path: Path,
) -> None:
    """A cache kept across versions (a developer's ``core/__pycache__`` held 43 folders,
    517 MB, after a week of edits): a start marks its fingerprint folder used and removes
    the other versions' folders but the 3 used last; nothing else in the folder is touched."""
    src = tmp_path / "src"
    pkg = _package(src)
    cache = tmp_path / "cache"
    old = [cache / f"{i:016x}" for i in range(6)]
    for age, folder in enumerate(old):
        (folder / "sub").mkdir(parents=True)
        os.utime(folder, (1e9 - age * 86400, 1e9 - age * 86400))  # 0 used last
    (cache / "notes").mkdir()
    (cache / "other.txt").write_text("not ours")
    assert _run(src, cache)[0] == "1 0 1"
    mark = fingerprint(pkg)
    kept = {mark, *(f.name for f in old[:3]), "notes", "other.txt"}
    assert {p.name for p in cache.iterdir()} == kept
    (pkg / "consts.py").write_text("K = 2\n")  # the next version: the first one kept too
    assert _run(src, cache)[0] == "2 0 1"
    assert {p.name for p in cache.iterdir()} == (kept - {old[2].name}) | {fingerprint(pkg)}


def test_workers_starting_together_share_one_copy_of_the_seed(
    seeded: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    """``--workers N``: every worker copies into its own folder and renames it; the first
    rename wins, the others use the winner's copy; each loads the kernel, none compiles."""
    src, pkg, seed = seeded
    cache = tmp_path / "cache"
    cache.mkdir()
    pipe = subprocess.PIPE
    command = [sys.executable, "-P", "-c", "import pkg.kern"]
    env = _env(src, cache, seed)
    procs = [
        subprocess.Popen(command, env=env, stdout=pipe, stderr=pipe, text=True) for _ in range(4)
    ]
    outs = [p.communicate(timeout=60) for p in procs]
    assert [o.strip() for o, _ in outs] == ["1 1 0"] * 4, [e[-2000:] for _, e in outs]
    assert sorted(p.name for p in cache.iterdir()) == [fingerprint(pkg)]


def test_a_copy_that_loses_the_race_is_removed_and_the_winners_kept(tmp_path: Path) -> None:
    source = tmp_path / "seed" / "mark"
    (source / "sub").mkdir(parents=True)
    (source / "sub" / "k.nbi").write_bytes(b"seed")
    folder = tmp_path / "cache" / "mark"
    folder.mkdir(parents=True)
    assert core.jit._seed(source, folder)  # onto an empty folder: copied
    assert (folder / "sub" / "k.nbi").read_bytes() == b"seed"
    (folder / "sub" / "k.nbi").write_bytes(b"winner")
    assert not core.jit._seed(source, folder)  # another process's came first
    assert (folder / "sub" / "k.nbi").read_bytes() == b"winner"
    assert sorted(p.name for p in folder.parent.iterdir()) == ["mark"]


def _warning(err: list[str]) -> dict[str, str]:
    (line,) = [json.loads(x) for x in err]  # one line, JSON as every line of the service
    assert line["event"] == "kernel_seed_unused", line
    return dict(line)


def test_a_seed_of_other_sources_is_not_used_and_a_warning_says_so(tmp_path: Path) -> None:
    src = tmp_path / "src"
    pkg = _package(src)
    seed = _seed(tmp_path, src)
    (pkg / "consts.py").write_text("K = 2\n")  # the code changed since the seed was made
    cache = tmp_path / "cache"
    cache.mkdir()
    line, err = _run(src, cache, seed)
    assert line == "2 0 1"  # compiled, the stale kernel (1) not loaded
    said = _warning(err)
    assert said["folder"] == str(cache / fingerprint(pkg)) and said["seed"] == str(seed)
    assert "compiled from other code" in said["detail"] and "compile" in said["detail"]
    assert [p.name for p in cache.iterdir()] == [fingerprint(pkg)]


def test_a_seed_compiled_at_another_path_is_not_used_and_a_warning_says_so(
    seeded: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    """numba names its cache folder after the sources' absolute path: the same sources
    installed elsewhere do not find the seed's kernels (the image compiles the seed from
    the installed /opt/marionette/app for this reason)."""
    src, _, seed = seeded
    elsewhere = tmp_path / "elsewhere"
    shutil.copytree(src, elsewhere, ignore=shutil.ignore_patterns("__pycache__"))
    cache = tmp_path / "cache"
    cache.mkdir()
    line, err = _run(elsewhere, cache, seed)
    assert line == "1 0 1"
    assert "compiled from sources at another path" in _warning(err)["detail"]


def test_an_unwritable_cache_folder_is_refused(tmp_path: Path) -> None:
    """numba checks its folder by writing a file there and, failing that, keeps nothing (or
    falls back to ``__pycache__``, without the fingerprint) without a word: a start that
    compiled for about a minute every time. Refused instead, naming the folder."""
    src = tmp_path / "src"
    _package(src)
    (tmp_path / "file").write_text("")
    cache = tmp_path / "file" / "cache"  # under a file: cannot be made
    out = subprocess.run(
        [sys.executable, "-P", "-c", "import pkg.kern"],
        env=_env(src, cache), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert out.returncode == 1 and "CacheDirError" in out.stderr, out.stderr[-2000:]
    assert f"{cache}/" in out.stderr and "set NUMBA_CACHE_DIR to a writable" in out.stderr
    assert not list((src / "pkg").glob("__pycache__/*.nbi"))  # no fallback either


def test_pose_service_refuses_an_unwritable_numba_cache_dir_in_one_json_line(
    tmp_path: Path,
) -> None:
    (tmp_path / "file").write_text("")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "MARIONETTE_"))}
    env |= {
        "NUMBA_CACHE_DIR": str(tmp_path / "file" / "cache"),
        "POSE_MODELS_DIR": str(tmp_path / "no-models"),  # (a later refusal, were it started)
    }
    proc = subprocess.run(
        [sys.executable, "-c", "from service.cli import main; main([])"],
        cwd=REPO_ROOT, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    (line,) = [json.loads(x) for x in proc.stderr.splitlines()]
    assert line["event"] == "start_refused", line
    assert "no writable folder for the compiled kernels' cache" in line["detail"]
    assert str(tmp_path / "file" / "cache") in line["detail"]
