"""Does a far reach fold the shoulders? ``python -m bench.chest [--poses 60] [--data-only]``.

Two tables (docs/kinematics.md, "Far reaches fold the shoulders"):

1. **Real motion**: pairs of frames 0.2-1 s apart in world space, seeded, per split (TRAIN,
   the held-out bodies; ``bench.edits.sample_pairs``, the training pair sampler): how far
   the collar-to-collar distance and the shoulder width change, how far each collar turns
   against the spine bone, and how far each clavicle strays from its mean direction in a
   chest frame (the spine bone and the collars' line: ``core.ends.CLAVICLE_CONE``).
2. **Far reaches** through :class:`service.engine.Engine` with the shipped models: one
   wrist moved 0.4-1.0 m in a seeded direction, both wrists of ``--poses`` real poses from
   each of TEST and the held-out bodies (:func:`bench.pins.sample_poses`), without and with
   both ankles pinned;
   neural soft, neural exact and FABRIK. Per method: answers whose shoulders ended nearer
   than 80 % and 60 % of the start's width (and the least), answers with the wrist within
   1 mm of its goal, and the mean miss.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import numpy.typing as npt
import typer

from bench.characters import Models
from core.skeleton import JOINT_INDEX as J

F64 = npt.NDArray[np.float64]
#: Answers whose shoulders are nearer than these shares of the start's width
FOLDS = (0.8, 0.6)
METHODS = (("neural", "soft"), ("neural", "exact"), ("fabrik", "soft"))


def _unit(v: F64) -> F64:
    out: F64 = v / np.linalg.norm(v, axis=-1, keepdims=True)
    return out


def _pct(x: F64) -> str:
    return " / ".join(f"{np.percentile(x, q):.2f}" for q in (50, 99, 99.9)) + f" / {x.max():.2f}"


def _chest_frame(w: F64, i: npt.NDArray[np.intp]) -> F64:
    """Per row ``i`` of world poses ``w``, the chest's frame (columns): across (the collars'
    line without its part along the spine bone), up (the spine bone), forward."""
    up = _unit(w[i, J["spine2"]] - w[i, J["spine1"]])
    ac = w[i, J["left_collar"]] - w[i, J["right_collar"]]
    ac = _unit(ac - np.sum(ac * up, -1, keepdims=True) * up)
    out: F64 = np.stack([ac, up, np.cross(ac, up)], -1)
    return out


def _gap(w: F64, i: npt.NDArray[np.intp], a: str, b: str) -> F64:
    out: F64 = np.linalg.norm(w[i, J[a]] - w[i, J[b]], axis=-1)
    return out


def real_motion(dataset: Path, pairs: int, seed: int) -> None:
    """Print table 1 (see the module)."""
    from bench.edits import sample_pairs
    from trainer.data.dataset import load_dataset

    data = load_dataset(dataset)
    print("| split | pairs | collar-collar change | width ratio, least | collar vs spine bone,"
          " deg (p50 / p99 / p99.9 / max) | clavicle from its mean, deg |")  # fmt: skip
    print("|---|---|---|---|---|---|")
    for split in ("train", "holdout"):
        part = data.subset(data.split_mask(split))
        w = part.world()
        a, b = sample_pairs(part, pairs, np.random.default_rng(seed))
        fa, fb = _chest_frame(w, a), _chest_frame(w, b)
        tilt, clav = [], []
        for side in ("left", "right"):
            c, s = J[f"{side}_collar"], J[f"{side}_shoulder"]
            va = np.einsum("nji,nj->ni", fa, _unit(w[a, c] - w[a, J["spine2"]]))
            vb = np.einsum("nji,nj->ni", fb, _unit(w[b, c] - w[b, J["spine2"]]))
            tilt.append(np.degrees(np.arccos(np.clip(np.sum(va * vb, -1), -1, 1))))
            v = np.einsum("nji,nj->ni", fa, _unit(w[a, s] - w[a, c]))
            clav.append(np.degrees(np.arccos(np.clip(v @ _unit(v.mean(0)), -1, 1))))
        cc = [_gap(w, i, "left_collar", "right_collar") for i in (a, b)]
        sw = [_gap(w, i, "left_shoulder", "right_shoulder") for i in (a, b)]
        print(
            f"| {split} | {len(a):,} | {np.abs(cc[1] / cc[0] - 1).max():.1e} | "
            f"{np.percentile(sw[1] / sw[0], 0.1):.3f} (p0.1), {(sw[1] / sw[0]).min():.3f} | "
            f"{_pct(np.concatenate(tilt))} | {_pct(np.concatenate(clav))} |"
        )


def far_reaches(models: Path, dataset: Path, poses: int, seed: int) -> None:
    """Print table 2 (see the module)."""
    from bench.pins import sample_poses
    from service.engine import Engine
    from service.problems import SolveProblem

    starts = sample_poses(dataset, poses, seed)
    engine = Engine(models, threads=1)
    rng = np.random.default_rng(seed + 3)
    cases = []
    for p in starts:
        for side in ("left", "right"):
            d = _unit(rng.normal(size=3))
            w = J[f"{side}_wrist"]
            cases.append((p, w, p[w] + d * rng.uniform(0.4, 1.0)))
    ankles = [J["left_ankle"], J["right_ankle"]]

    def width(p: npt.NDArray[np.floating]) -> float:
        return float(np.linalg.norm(p[J["left_shoulder"]] - p[J["right_shoulder"]]))

    print(f"| ankles pinned | method | answers | shoulders < {FOLDS[0]} / < {FOLDS[1]} | least |"
          " wrist within 1 mm | mean miss, cm |")  # fmt: skip
    print("|---|---|---|---|---|---|---|")
    for pinned in (False, True):
        for method, reach in METHODS:
            problems = []
            for p, w, g in cases:
                idx = np.array([w, *ankles] if pinned else [w], dtype=np.intp)
                goal = np.concatenate([g[None], p[ankles]]) if pinned else g[None]
                problems.append(SolveProblem(
                    pose=p, target_idx=idx, target_pos=goal, weights=np.ones(len(idx)),
                    n_targets=1, method=method, reach=reach, floor=float(p[:, 1].min()),
                ))  # fmt: skip
            got = engine.solve(problems)
            ratio = np.array([width(r.pose) / width(c[0]) for r, c in zip(got, cases, strict=True)])
            miss = np.array(
                [np.linalg.norm(r.pose[w] - g) for r, (_, w, g) in zip(got, cases, strict=True)]
            )
            print(
                f"| {'yes' if pinned else 'no'} | {method} {reach} | {len(cases)} | "
                f"{int((ratio < FOLDS[0]).sum())} / {int((ratio < FOLDS[1]).sum())} | "
                f"{ratio.min():.2f} | {int((miss <= 1e-3).sum())} | {100 * miss.mean():.2f} |"
            )


def main(
    models: Models = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = Path(
        "data/poses.npz"
    ),
    poses: Annotated[int, typer.Option(min=1, help="Real poses per split (TEST, held-out).")] = 60,
    pairs: Annotated[int, typer.Option(min=1, help="Frame pairs drawn per split.")] = 200_000,
    seed: Annotated[int, typer.Option(help="Seed of the pairs, poses and directions.")] = 7,
    data_only: Annotated[bool, typer.Option(help="Only the real-motion table.")] = False,
) -> None:
    """Print the real-motion table, then the far-reach table."""
    real_motion(dataset, pairs, seed)
    if not data_only:
        print()
        far_reaches(models, dataset, poses, seed)


if __name__ == "__main__":
    typer.run(main)
