"""The compiled kernels' disk cache follows every source they read constants from."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import core.jit
from core.jit import fingerprint

CORE = Path(core.jit.__file__).resolve().parent

KERNEL = """from pkg.consts import K
from pkg.jit import jit


@jit
def f() -> int:
    return K


print(f())
"""


def _run(root: Path, cache: Path) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("NUMBA_", "MARIONETTE_"))}
    env |= {"PYTHONPATH": str(root), "NUMBA_CACHE_DIR": str(cache)}
    out = subprocess.run(
        [sys.executable, "-B", "-c", "import pkg.kern"], env=env, capture_output=True, text=True
    )  # (-B: no .pyc of consts.py, which CPython would check by mtime in whole seconds and size
    # only: K = 2 written within the second of K = 1 read the stale one; test_jit_seed.py)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip()


def test_a_constant_edited_in_another_module_is_not_served_from_a_stale_cache(
    tmp_path: Path,
) -> None:
    """A kernel bakes in a constant imported from another file; numba alone checks only the
    kernel's own file, so without the sources' fingerprint in the cache folder the second
    run would load the first run's machine code and print 1."""
    pkg = tmp_path / "src" / "pkg"
    pkg.mkdir(parents=True)
    shutil.copy(CORE / "jit.py", pkg / "jit.py")
    (pkg / "__init__.py").write_text("")
    (pkg / "kern.py").write_text(KERNEL)
    (pkg / "consts.py").write_text("K = 1\n")
    cache = tmp_path / "cache"
    assert _run(tmp_path / "src", cache) == "1"
    assert _run(tmp_path / "src", cache) == "1"  # loaded, the same folder
    first = fingerprint(pkg)
    (pkg / "consts.py").write_text("K = 2\n")
    assert fingerprint(pkg) != first
    assert _run(tmp_path / "src", cache) == "2"
    assert sorted(p.name for p in cache.iterdir()) == sorted([first, fingerprint(pkg)])


def test_this_process_and_its_children_use_the_core_sources_folder() -> None:
    """numba reads the folder named by core's fingerprint, and a child process inheriting
    the environment picks the same one (not a folder inside it)."""
    folder = core.jit.numba.config.CACHE_DIR  # numba as core.jit imported it
    assert Path(folder).name == fingerprint(CORE)
    out = subprocess.run(
        [sys.executable, "-c", "import core.jit, numba; print(numba.config.CACHE_DIR)"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert out.stdout.strip() == folder


#: Calls numba lowers through scipy's BLAS or LAPACK, which the service image leaves out
BLAS = {"dot", "vdot", "inner", "matmul"}


def test_no_compiled_kernel_calls_blas() -> None:
    """A kernel that used ``@`` on two 3-vectors compiled here (scipy is installed for
    training) and broke the image's build at ``compiled.warm()``: numba lowers ``@``,
    ``np.dot`` and ``np.linalg`` through scipy's BLAS and LAPACK, which the slim image has
    not (CI, 2026-12-07). Every function decorated ``@jit`` in ``core`` is read for them."""
    import ast

    found = []
    for path in sorted(CORE.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.FunctionDef):
                continue
            if not any(isinstance(d, ast.Name) and d.id == "jit" for d in node.decorator_list):
                continue
            for inner in ast.walk(node):
                bad = isinstance(inner, ast.BinOp) and isinstance(inner.op, ast.MatMult)
                if isinstance(inner, ast.Attribute):
                    bad = bad or inner.attr in BLAS or inner.attr == "linalg"
                if bad:
                    found.append(f"{path.name}:{inner.lineno} in {node.name}")
    assert not found, found
    assert len(list(CORE.glob("compiled*.py"))) >= 6  # (the kernels were read)
