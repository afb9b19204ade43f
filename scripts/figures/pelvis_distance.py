"""How far a character's pelvis ends from the canonical answer's on exact edits whose
targets the answer met (docs/characters.md, "What the character is held to": targets the
answer met do not carry the body across).

Five studios' BVH files (``tests.character_files.FILES``, extracted from the mocap
archives in ``--mocap``), each edited at its test frame in exact reach: the head, the left
elbow, the right wrist or both wrists moved 10-40 cm (the character's own metres) in
seeded directions, ``--reps`` times per file and set, each without pins and with both
ankles pinned. Kept: the edits whose canonical answer met every target and pin (as
``tests/service/test_character_reach.py -k carry`` keeps them). Printed: how many, the
distance of the character's pelvis (its canonical point) from the answer's (p50, p90,
max, mm; the three farthest), its worst pin (mm), and every edit where the character
misses a target the answer met (``reached: false``), with its miss; with ``--best``, also
the nearest a search on the character's own skeleton finds (:func:`own_best`: whether the
miss is the retarget's or the skeleton's).

    MARIONETTE_MOCAP=/work/shared/mocap python scripts/figures/pelvis_distance.py [--reps 5]
        [--best]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from core.characters import Pose
from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX
from service.bvh_models import BVHSolveRequest
from service.character_bvh import character_from_bvh, read_request_bvh
from service.characters import Character, Edit, character_problem, solve_prepared
from service.engine import Engine
from tests.character_files import FILES, extract_bvh

REPO = Path(__file__).resolve().parents[2]
MOCAP = Path(os.environ.get("MARIONETTE_MOCAP", REPO.parent / "shared" / "mocap"))
PELVIS = JOINT_INDEX["pelvis"]
SETS: tuple[tuple[str, ...], ...] = (
    ("head",), ("left_elbow",), ("right_wrist",), ("left_wrist", "right_wrist"),
)  # fmt: skip
PINS = ("left_ankle", "right_ankle")


def edits(path: Path, name: str, reps: int, rng: np.random.Generator) -> list[dict[str, Any]]:
    """``/v1/bvh/solve`` bodies of one file: every set ``reps`` times, without pins and
    with both ankles pinned (the same move for both)."""
    text = path.read_text()
    _, _, units, frame = FILES[name]
    base: dict[str, Any] = {"bvh": text, "frame": frame, "options": {"reach": "exact"},
                            "targets": [{"joint": "head", "position": [0, 0, 0]}]}  # fmt: skip
    if units is not None:
        base["units"] = units
    ch = character_from_bvh(read_request_bvh(text), BVHSolveRequest.model_validate(base), frame)
    pts = canonical_points(ch.skel, ch.pose, ch.jmap)
    label = ch.jmap.describe()
    out = []
    for joints in SETS:
        for _ in range(reps):
            targets = []
            for j in joints:
                way = rng.normal(size=3)
                move = way / np.linalg.norm(way) * rng.uniform(0.1, 0.4) / ch.scale
                targets.append(
                    {"joint": label[j], "position": (pts[JOINT_INDEX[j]] + move).tolist()}
                )
            for pins in ((), PINS):
                what = f"{name}: {'+'.join(joints)}{', ankles pinned' if pins else ''}"
                pinned = [label[p] for p in pins]
                out.append({**base, "targets": targets, "pins": pinned, "_what": what})
    return out


def own_best(ch: Character, edit: Edit, starts: int = 12, seed: int = 0) -> tuple[float, float]:
    """The nearest the character's own skeleton was found to come to the targets of an edit
    with its pins held: the targets' farthest miss and the pins' (metres). SciPy's
    least squares (Levenberg-Marquardt) over a turn of every rotatable joint above a target
    or pin and a move of the joint that places the pelvis (the one ``core.retarget``
    moves: every other keeps its offset), the pins weighing 1000 targets, from the
    retarget's answer, the pose as sent, and turns of those joints drawn at random about
    both (0.8 and 0.3 rad); a search, so an upper bound of the character's best."""
    from scipy.optimize import least_squares  # (dev dependency: the figure only)
    from scipy.spatial.transform import Rotation

    p = edit.problem
    goals = np.array([ch.from_service(g) for g in p.target_pos])
    joints = [int(j) for j in p.target_idx]
    k = p.n_targets
    above: set[int] = set()
    for j in joints:
        b = int(ch.jmap.joints[j])
        while b >= 0:
            above.add(b)
            b = ch.skel.parents[b]
    turns = [b for b in sorted(above) if ch.skel.rotatable[b]]
    # the joint the retarget moves (every other keeps its offset: the character's lengths)
    t = int(ch.jmap.joints[JOINT_INDEX["pelvis"]])
    while t >= 0 and not ch.skel.translatable[t]:
        t = ch.skel.parents[t]
    moves = [t] if t >= 0 else []
    weight = np.repeat(np.r_[np.ones(k), np.full(len(joints) - k, 1e3)], 3)

    def pose_of(x: np.ndarray, base: Pose) -> Pose:
        rot, pos = base.rotations.copy(), base.translations.copy()
        turn = Rotation.from_rotvec(x[: 3 * len(turns)].reshape(-1, 3)).as_matrix()
        rot[turns] = rot[turns] @ turn
        pos[moves] += x[3 * len(turns) :].reshape(-1, 3)
        return Pose(rot, pos)

    def misses(x: np.ndarray, base: Pose) -> np.ndarray:
        pts = canonical_points(ch.skel, pose_of(x, base), ch.jmap)[joints]
        return np.asarray(np.linalg.norm(pts - goals, axis=1) * ch.scale)

    def residuals(x: np.ndarray, base: Pose) -> np.ndarray:
        pts = canonical_points(ch.skel, pose_of(x, base), ch.jmap)[joints]
        return np.concatenate([(pts - goals).ravel() * weight, 1e-3 * x])

    rng = np.random.default_rng(seed)
    n = 3 * (len(turns) + len(moves))
    best = (np.inf, np.inf)
    for i in range(starts):
        base = (edit.pose, ch.pose)[i % 2]
        x0 = np.zeros(n) if i < 2 else rng.normal(scale=0.8 if i < starts // 2 else 0.3, size=n)
        x = least_squares(residuals, x0, args=(base,), method="lm", max_nfev=4000).x
        miss = misses(x, base)
        out = (float(miss[:k].max()), float(miss[k:].max(initial=0.0)))
        if out[1] <= p.tolerance and out[0] < best[0]:
            best = out
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", type=Path, default=Path("models"))
    ap.add_argument("--mocap", type=Path, default=MOCAP, help="the mocap archives' folder")
    ap.add_argument("--reps", type=int, default=5, help="moves per file and target set")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--best", action="store_true", help="search the character's own best")
    args = ap.parse_args()

    engine = Engine(args.models, threads=1)
    rng = np.random.default_rng(args.seed)
    pelvis: list[float] = []
    names: list[str] = []
    pin_worst, missed, total = 0.0, [], 0
    with tempfile.TemporaryDirectory() as tmp:
        files = extract_bvh(args.mocap, Path(tmp))
        for name in sorted(files):
            for body in edits(files[name], name, args.reps, rng):
                total += 1
                what = body.pop("_what")
                req = BVHSolveRequest.model_validate(body)
                ch = character_from_bvh(read_request_bvh(body["bvh"]), req, req.frame)
                edit = solve_prepared(engine, ch, character_problem(ch, req))
                res, p = edit.result, edit.problem
                if (res.errors > p.tolerance).any() or (res.pin_errors > p.tolerance).any():
                    continue  # (the canonical answer misses: not this figure's case)
                got = ch.to_service(canonical_points(ch.skel, edit.pose, ch.jmap))
                miss = np.linalg.norm(got[p.target_idx] - p.target_pos, axis=1)
                pelvis.append(float(np.linalg.norm(got[PELVIS] - res.pose[PELVIS])))
                names.append(what)
                if miss.size > p.n_targets:
                    pin_worst = max(pin_worst, float(miss[p.n_targets :].max()))
                if (miss[: p.n_targets] > p.tolerance).any():
                    line = f"{what}: {miss[: p.n_targets].max() * 1e3:.1f} mm"
                    if args.best:
                        best = own_best(ch, edit)[0] * 1e3
                        line += f" (its own skeleton's best found: {best:.1f} mm)"
                    missed.append(line)
    mm = np.asarray(pelvis) * 1e3
    print(f"models {engine.version}; {len(mm)} of {total} exact edits the answer met "
          f"(seed {args.seed}, {args.reps} per file, set and pin mode)")  # fmt: skip
    p50, p90 = np.percentile(mm, [50, 90])
    print(f"pelvis from the answer's (mm): p50 {p50:.1f}, p90 {p90:.1f}, max {mm.max():.1f}; "
          f"worst pin {pin_worst * 1e3:.3f} mm")  # fmt: skip
    far = np.argsort(-mm)[:3]
    print("farthest: " + "; ".join(f"{names[i]} {mm[i]:.1f} mm" for i in far))
    print(f"a target the answer met missed by the character: {len(missed)}")
    for line in missed:
        print(f"  {line}")


if __name__ == "__main__":
    main()
