"""``python -m bench.ab``: two revisions' single-edit times side by side in one run.

The probes read the small real dataset (``holdout_dataset``), not data/poses.npz where it
was built (``bench_dataset``): what is checked here is the table and the worktree, not the
figures, and each probe spent ~3 s reading the 131 MB file."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

from bench import ab

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_two_revisions_side_by_side(
    holdout_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A worktree of HEAD against this tree: every case timed in both, each round, and
    the worktree gone afterwards (its temporary folder under ``tmp_path``: worktrees that
    others add to a shared checkout meanwhile are theirs)."""
    if subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], check=False).returncode:
        pytest.skip("not a git checkout")

    def worktrees() -> set[str]:
        """The worktrees' paths (not their commits: another worktree may commit meanwhile)."""
        out = subprocess.run(["git", "-C", str(REPO), "worktree", "list", "--porcelain"],
                             capture_output=True, text=True, check=True).stdout  # fmt: skip
        return {line.split(" ", 1)[1] for line in out.splitlines() if line.startswith("worktree ")}

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    # A fresh checkout (CI) has no compiled kernels yet: this tree's probe first compiles
    # them, so that a base whose core/ is this tree's (HEAD) gets copies of them
    # (ab.share_kernels) instead of compiling them all again (~45 s of the suite).
    mine = ab._kernels_dir(REPO)
    if mine is None or not any(mine.glob("*.nbi")):
        assert set(ab._run(REPO, holdout_dataset, 4, 0)) >= {"1 default", "bvh soft"}
    result = ab.compare("HEAD", holdout_dataset, rounds=1, edits=4, seed=0)
    cases = {f"{k} {c}" for k in (1, 2, 5) for c in ("default", "plain", "fabrik", "batch")}
    cases |= {"1 pinned", "2 pinned", "bvh exact", "bvh soft", "bvh soft cold", "character"}
    for side in ("base", "this"):
        assert len(result[side]) == 1 and set(result[side][0]) == cases
        assert all(0 < t < 1e6 for t in result[side][0].values())
    text = ab.table(result)
    assert text.count("\n") == 2 + len(cases) - 1 and "| 2 pinned |" in text
    assert list(tmp_path.iterdir()) == []  # the base's worktree made there, and removed
    assert not {w for w in worktrees() if w.startswith(str(tmp_path))}


@pytest.mark.slow
def test_a_probe_that_fails_says_why(holdout_dataset: Path, tmp_path: Path) -> None:
    """A tree the probe cannot run in (here: no models) is an error with its reason."""
    with pytest.raises(RuntimeError, match="the probe failed") as err:
        ab._run(tmp_path, holdout_dataset, 1, 0)
    assert "Error" in str(err.value)  # the probe's own traceback, not a bare exit status


@pytest.mark.slow
def test_a_serving_setting_against_the_models_own(holdout_dataset: Path) -> None:
    """``--serving`` without ``--base``: this tree against itself, its side served with the
    setting. One that changes nothing the probe times (``keep_pelvis`` 0, the shipped
    value) times the same cases; the table names the setting; a setting the models refuse
    fails the probe, so the setting does reach the engine."""
    result = ab.compare(None, holdout_dataset, rounds=1, edits=4, seed=0,
                        serving={"keep_pelvis": 0.0})  # fmt: skip
    assert result["serving"] == {"keep_pelvis": 0.0}
    assert set(result["base"][0]) == set(result["this"][0]) and "5 batch" in result["this"][0]
    text = ab.table(result)
    assert "this tree (models' settings)" in text.splitlines()[0]
    assert "this tree keep_pelvis=0.0" in text.splitlines()[0]
    with pytest.raises(RuntimeError, match="passes"):
        ab._run(REPO, holdout_dataset, 1, 0, {"passes": 0})


@pytest.mark.slow
def test_a_base_with_the_same_kernels_sources_gets_this_trees_compiled_kernels(
    tmp_path: Path,
) -> None:
    """The base's probe compiled every kernel again (a minute or more) when its ``core/``
    was this tree's: numba names its folder after the sources' path. Now this tree's
    compiled kernels are copied into the worktree's folder, and numba there loads them
    (``stats.cache_hits``) instead of compiling."""
    import numpy as np

    from core.compiled import shortest_bones

    shortest_bones(np.zeros((1, 21, 3)))  # (compiled, or loaded, into this tree's cache)
    tree = tmp_path / "base"
    subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q", str(tree),
                    "HEAD"], check=True)  # fmt: skip
    kernels = None
    try:
        for path in (REPO / "core").glob("*.py"):  # this tree's core/, edits and all
            (tree / "core" / path.name).write_bytes(path.read_bytes())
        mine = ab._kernels_dir(REPO)
        kernels = ab.share_kernels(tree)
        assert mine is not None and kernels is not None and kernels != mine
        assert {p.name for p in mine.iterdir()} <= {p.name for p in kernels.iterdir()}
        code = ("import numpy as np, core.compiled as c; c.shortest_bones(np.zeros((1, 21, 3)));"
                " print(sum(c.shortest_bones.stats.cache_hits.values()))")  # fmt: skip
        env = {**os.environ, "PYTHONPATH": str(tree)}
        done = subprocess.run([sys.executable, "-c", code], cwd=tree, env=env,
                              capture_output=True, text=True, check=True)  # fmt: skip
        assert int(done.stdout.split()[-1]) >= 1, done.stdout
    finally:
        if kernels is not None and not kernels.is_relative_to(tree):
            shutil.rmtree(kernels, ignore_errors=True)
        subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)],
                       check=False)  # fmt: skip
