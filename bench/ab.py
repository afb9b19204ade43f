"""Single-edit engine time of two revisions side by side, on this machine, in one run:
``python -m bench.ab --base REV [--rounds 3] [--edits 128]``.

This machine is shared and noisy: one revision's timings from one run against another's
from another run compare hosts as much as code. Here each round runs a probe (this file,
``--probe``) in a git worktree of ``REV`` and then in this tree, each in a fresh process,
the same edits in the same order; the rounds alternate. The probe times
``Engine.solve([p])`` per call in CPU time of its thread (``time.thread_time_ns``: another
tenant's load on the host shows less in it than in wall time), for 1, 2 and 5 targets (the
TEST split's B1-style edits, the speed part's seed): the models' defaults (``default``),
one pass without the mirror image (``plain``: the paper's configuration), FABRIK
(``fabrik``), and with both ankles pinned where the start has them (``pinned``, 1 and 2
targets); and a client's own character, a BVH file's frame edited end to end but for HTTP
(``bvh exact``, ``bvh soft``; ``bvh soft cold``: each call a file whose hierarchy is new to
the probe; :func:`bvh_edits`) or its joints in JSON (``character``). The table gives each
case's p50 per round, and the best round of each revision (the least disturbed) with their
ratio.

A base whose ``core/`` sources are this tree's gets this tree's compiled kernels
(:func:`share_kernels`: it compiled them all again, a minute or more); the worktree's
kernels do not outlive it.

The probe uses only what both trees have (``Engine``, ``bench.edits``; the ``bvh`` rows where
the base has the character routes); the models are
each tree's own.

``--serving KEY=VALUE`` (repeatable) times this tree with those serving settings against
itself with the models' own (no ``--base``), or against ``--base`` as it is: the A/B of a
setting, such as ``turn_quick=true`` (docs/generalisation-serving-2.md item 40). The
``batch`` rows time each case's edits as one ``Engine.solve`` call, per edit.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from importlib import import_module
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

REPO = Path(__file__).resolve().parents[1]
SETS = {
    1: ("left_wrist",),
    2: ("left_wrist", "right_wrist"),
    5: ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle"),
}


def ankles_pinned(problems: list[Any]) -> list[Any]:
    """``problems`` (``SolveProblem``) with both ankles pinned where each start has them,
    as an editor pins the feet (sets with an ankle target: empty). Also ``make bench``'s
    ``neural_pinned`` (:mod:`bench.speed`); here, not in :mod:`bench.edits`, because the
    probe also runs in older trees."""
    from core.skeleton import JOINT_INDEX

    ankles = np.asarray([JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]])
    if not problems or np.isin(ankles, problems[0].target_idx).any():
        return []
    return [
        dataclasses.replace(
            p, target_idx=np.concatenate([p.target_idx, ankles]),
            target_pos=np.concatenate([p.target_pos, p.pose[ankles]]),
            weights=np.ones(len(p.target_idx) + 2),
        )
        for p in problems
    ]  # fmt: skip


def probe(
    dataset: Path, edits: int, seed: int, serving: dict[str, Any] | None = None
) -> dict[str, float]:
    """Per case, the p50 in µs of ``Engine.solve([p])`` over three calls of each edit, and
    (``batch``) the median over three calls of ``Engine.solve`` on all of them, per edit;
    ``serving``: settings over the models' own."""
    from bench.edits import edits_from_pairs, joint_idx, problems, sample_pairs, test_split
    from service.engine import Engine
    from trainer.data.dataset import load_dataset

    models = Path("models")  # (an older tree's Engine may not take ``serving``)
    engine = Engine(models, threads=1, serving=serving) if serving else Engine(models, threads=1)
    test = test_split(load_dataset(dataset))
    a, b = sample_pairs(test, edits, np.random.default_rng(seed + 100))
    out: dict[str, float] = {}
    for k, names in SETS.items():
        ed = edits_from_pairs(test, a, b, [joint_idx(names)] * len(a))
        neural = problems(ed, "neural_bone")
        cases = {
            "default": neural,
            "plain": [dataclasses.replace(p, passes=1, mirror=False) for p in neural],
            "fabrik": problems(ed, "fabrik"),
            "pinned": ankles_pinned(neural),  # none for the five end effectors
        }
        for name, probs in cases.items():
            if not probs:
                continue
            for p in probs[:10]:  # warm
                engine.solve([p])
            ns = []
            for _ in range(3):
                for p in probs:
                    t0 = time.thread_time_ns()
                    engine.solve([p])
                    ns.append(time.thread_time_ns() - t0)
            out[f"{k} {name}"] = float(np.median(ns)) / 1e3
        whole = []
        for _ in range(3):
            t0 = time.thread_time_ns()
            engine.solve(neural)
            whole.append((time.thread_time_ns() - t0) / len(neural))
        out[f"{k} batch"] = float(np.median(whole)) / 1e3
    out.update(bvh_edits(engine))
    out.update(character_edits(engine))
    return out


def bvh_edits(engine: Any, calls: int = 20) -> dict[str, float]:
    """The p50 in µs of a whole ``POST /v1/bvh/solve`` minus HTTP (``service.characters``:
    read the file, map its joints, solve, retarget, write the file back), over ``calls``
    calls of ``docs/examples/bvh_solve.json`` (22 joints, two pins) as given (``exact``) and
    in soft reach without its pins (``soft``). None in a tree without them (the table
    then leaves those rows out)."""
    try:
        from service.character_bvh import bvh_answer, character_from_bvh, read_request_bvh
        from service.characters import solve_character

        try:
            from service.bvh_models import BVHSolveRequest
        except ImportError:  # (a tree before the BVH models moved, 9d8e58b)
            from service.characters import BVHSolveRequest  # type: ignore[attr-defined,no-redef]
        body = json.loads(Path("docs/examples/bvh_solve.json").read_text())
    except (ImportError, FileNotFoundError):
        return {}
    # (a tree before 9d8e58b takes the frame from the request)
    framed = "frame" in inspect.signature(character_from_bvh).parameters
    soft = {**body, "pins": [], "options": {"reach": "soft"}}
    asks = {"exact": body, "soft": soft, "soft cold": soft}
    # (``cold``: each call a file whose hierarchy was not read before, where the tree keeps
    # the last ones read, core.bvh's SHARED: an editor's edits share one, a new user's not)
    forget = getattr(import_module("core.bvh"), "_shared", None)
    out: dict[str, float] = {}
    for name, ask in asks.items():
        req = BVHSolveRequest.model_validate(ask)

        def edit(req: Any = req) -> None:
            bvh = read_request_bvh(req.bvh, req.frame)
            ch = character_from_bvh(*((bvh, req, req.frame) if framed else (bvh, req)))
            bvh_answer(bvh, ch, req, solve_character(engine, ch, req))

        cold = forget.cache_clear if name.endswith("cold") and forget is not None else None
        out[f"bvh {name}"] = _p50_us(edit, calls, cold)
    return out


def _p50_us(call: Any, calls: int, before: Any = None) -> float:
    """The median CPU time of the thread (µs) of ``calls`` calls of ``call`` after three to
    warm, ``before`` (untimed) ahead of each."""
    ns = []
    for i in range(calls + 3):
        if before is not None:
            before()
        t0 = time.thread_time_ns()
        call()
        if i >= 3:
            ns.append(time.thread_time_ns() - t0)
    return float(np.median(ns)) / 1e3


def character_edits(engine: Any, calls: int = 20) -> dict[str, float]:
    """The p50 in µs of a whole character ``POST /v1/solve`` minus HTTP (read the joints,
    map them, solve, retarget, answer the rotations) over ``calls`` calls of
    ``docs/examples/character_solve.json`` (22 joints, both feet pinned, soft reach) as
    given (``character``); None in a tree without ``character_from_request``."""
    try:
        from service import characters as ch

        body = json.loads(Path("docs/examples/character_solve.json").read_text())
        req = ch.CharacterAliasRequest.model_validate(body)
        read, prepared = ch.character_from_request, ch.solve_prepared
    except (ImportError, AttributeError, FileNotFoundError):
        return {}

    def edit() -> None:
        c = read(req)
        ch.character_answer(c, prepared(engine, c, ch.character_problem(c, req)), req.rotations)

    return {"character": _p50_us(edit, calls)}


def _run(
    tree: Path, dataset: Path, edits: int, seed: int, serving: dict[str, Any] | None = None
) -> dict[str, float]:
    cmd = [sys.executable, str(Path(__file__).resolve()), "--probe", str(dataset.resolve()),
           str(edits), str(seed), json.dumps(serving or {})]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, check=False)
    if done.returncode:  # say why (a revision without the probe's modules, say)
        raise RuntimeError(f"the probe failed in {tree}:\n{done.stderr[-2000:]}")
    got: dict[str, float] = json.loads(done.stdout.strip().splitlines()[-1])
    return got


#: Printed by a probe's interpreter in a tree: the folder its compiled kernels go in (the
#: cache folder ``core.jit`` chose, whose name is the fingerprint of ``core/``'s sources,
#: and numba's folder for them in it, named after their path).
_KERNELS = (
    "import os, core.jit as j; "
    "print(os.path.join(os.environ['NUMBA_CACHE_DIR'], "
    "j.numba_subfolder(os.path.dirname(os.path.abspath(j.__file__)))))"
)


def _kernels_dir(tree: Path) -> Path | None:
    """Where a probe in ``tree`` keeps its compiled kernels (None: a revision that cannot
    say, from before ``core.jit.numba_subfolder``)."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run([sys.executable, "-c", _KERNELS], cwd=tree, env=env,
                          capture_output=True, text=True, check=False)  # fmt: skip
    out = done.stdout.strip()
    return Path(out) if done.returncode == 0 and out else None


def share_kernels(tree: Path) -> Path | None:
    """Give the worktree ``tree`` this tree's compiled kernels where its ``core/`` sources
    are the same (the fingerprint its cache folder is named after): numba checks a cached
    kernel against its source's contents but keeps it in a folder named after the source's
    path, so the base's probe compiled every kernel again (a minute or more) for sources it
    had already. The folder the worktree's kernels go in (None: it cannot say)."""
    mine, theirs = _kernels_dir(REPO), _kernels_dir(tree)
    if theirs is None or mine is None or mine.parent.name != theirs.parent.name:
        return theirs  # (other sources: the base compiles its own)
    if mine.is_dir() and not (theirs.is_dir() and any(theirs.iterdir())):  # (asking made it)
        shutil.copytree(mine, theirs, dirs_exist_ok=True)
    return theirs


def compare(
    base: str | None, dataset: Path, rounds: int, edits: int, seed: int,
    serving: dict[str, Any] | None = None,
) -> dict[str, Any]:  # fmt: skip
    """The probe's figures of ``base`` (None: this tree with the models' own settings) and
    of this tree with ``serving``, ``rounds`` rounds alternated."""
    runs: dict[str, list[dict[str, float]]] = {"base": [], "this": []}

    def alternate(tree: Path) -> None:
        for _ in range(rounds):
            runs["base"].append(_run(tree, dataset, edits, seed))
            runs["this"].append(_run(REPO, dataset, edits, seed, serving))

    if base is None:
        alternate(REPO)
    else:
        with tempfile.TemporaryDirectory() as tmp:
            tree = Path(tmp) / "base"
            subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", "-q",
                            str(tree), base], check=True)  # fmt: skip
            kernels = None
            try:
                kernels = share_kernels(tree)
                alternate(tree)
            finally:
                if kernels is not None and not kernels.is_relative_to(tree):
                    shutil.rmtree(kernels, ignore_errors=True)  # (in this tree's cache: gone)
                subprocess.run(["git", "-C", str(REPO), "worktree", "remove", "--force",
                                str(tree)], check=False)  # fmt: skip
    label = "this tree (models' settings)" if base is None else base
    return {"revision": label, "serving": serving or {}, "rounds": rounds, "edits": edits, **runs}


def table(result: dict[str, Any]) -> str:
    """Markdown: per case the rounds' p50s and the best round of each, with their ratio."""
    mine = "this tree" + "".join(f" {k}={v}" for k, v in result.get("serving", {}).items())
    lines = [
        f"| case | {result['revision']} (µs, each round) | {mine} | best: "
        f"{result['revision']} → {mine} | × |",
        "|---|---|---|---|---|",
    ]
    for case in result["this"][0]:
        old = [r[case] for r in result["base"] if case in r]
        new = [r[case] for r in result["this"]]
        if not old:
            continue
        lines.append(
            f"| {case} | {' / '.join(f'{x:.0f}' for x in old)} | "
            f"{' / '.join(f'{x:.0f}' for x in new)} | {min(old):.0f} → {min(new):.0f} | "
            f"{min(old) / min(new):.2f} |"
        )
    return "\n".join(lines)


def main(
    base: Annotated[
        str | None,
        typer.Option(help="The revision to compare with (git); none: this tree itself."),
    ] = None,
    serving: Annotated[
        list[str] | None,
        typer.Option(help="KEY=VALUE: this tree's side served with this setting (repeat)."),
    ] = None,
    dataset: Annotated[Path, typer.Option(help="Dataset file.")] = Path("data/poses.npz"),
    rounds: Annotated[int, typer.Option(min=1, help="Rounds, each revision once.")] = 3,
    edits: Annotated[int, typer.Option(min=1, help="Edits per case.")] = 128,
    seed: Annotated[int, typer.Option(help="The edits' seed.")] = 0,
    out: Annotated[Path | None, typer.Option(help="Write the figures (JSON) here.")] = None,
) -> None:
    """Time single edits of REV and of this tree side by side (see the module)."""
    from bench.heldout import overrides

    asked = overrides(serving or [])
    if base is None and not asked:
        raise typer.BadParameter("give --base REV, --serving KEY=VALUE, or both")
    result = compare(base, dataset, rounds, edits, seed, asked)
    if out is not None:
        out.write_text(json.dumps(result, indent=1))
    print(table(result))


if __name__ == "__main__":
    if len(sys.argv) == 6 and sys.argv[1] == "--probe":
        args = Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), json.loads(sys.argv[5])
        print(json.dumps(probe(*args)))
    else:
        typer.run(main)
