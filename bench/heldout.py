"""Held-out bodies: world-space edits on bodies no model was trained on, and a stress set
of in-studio test poses rebuilt as other bodies (issue 11).

``python -m bench.heldout --models DIR --dataset FILE --out FILE.json [--quick]
[--captured] [--serving KEY=VALUE ...]`` runs only this part and prints one compact table
(``--serving``: the models served with other settings of their manifest's serving block,
``core.manifest.serving_with``); ``python -m bench`` runs it inside the full benchmark.
Everything goes through :class:`service.engine.Engine` in-process (the code the service
runs), with the options of the B1 benchmark.

Edits (per family: one held-out source, all held-out sources pooled, or a stress body):
two frames i, j of one clip, 0.2-1 s apart (6-30 frames at 30 fps, seeded); the target
pose is the WORLD pose of frame j, the start is the world pose of frame i translated so
that its pelvis lies on frame j's pelvis (the body may have turned between the two).
Targets are the target pose's joints of each set: every single-joint solver joint, both
wrists, both ankles, the five end effectors, random subsets of 2-6 solver joints (fresh
pairs), and 6-point completion (the target's six base key points -> ``Engine.complete``).
Methods: the start pose unchanged, FABRIK, neural + bone pass (soft), neural + exact
reach. Plus the autoencoder's reconstruction error (``Engine.reconstruct``) on held-out
poses. Metrics are in centimetres; bone error is relative to the start pose's lengths.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Optional

import numpy as np
import numpy.typing as npt
import typer
from pydantic import ValidationError

from bench.edits import (
    CM,
    END_EFFECTORS,
    FIVE,
    FLOOR_JOINTS,
    Edits,
    joint_idx,
    sample_pairs,
    solve,
    solver_joints,
)
from bench.metrics import paired_interval, per_item
from core.bodies import body_lengths, random_bodies, rebuild
from core.ends import SOFT_IK_MAX
from core.io import write_atomic
from core.skeleton import (
    BASE_KEYPOINTS,
    BONE_CHILDREN,
    JOINT_INDEX,
    JOINT_NAMES,
    NUM_JOINTS,
    bone_lengths,
)
from service.engine import Engine
from trainer.data.dataset import PoseDataset

F64 = npt.NDArray[np.floating[Any]]
IntArray = npt.NDArray[np.intp]

#: Methods of every held-out table, in column order (``completion``: the 6-point set only).
METHODS: tuple[str, ...] = ("identity", "fabrik", "neural_bone", "neural_exact")
COMPLETION = "6-point completion"
RANDOM_SET = "random 2–6 joints"
PAIRS: dict[str, tuple[str, ...]] = {
    "left_wrist+right_wrist": ("left_wrist", "right_wrist"),
    "left_ankle+right_ankle": ("left_ankle", "right_ankle"),
}
#: Turn buckets (degrees of yaw between the start and the target frame).
TURN_EDGES: tuple[float, ...] = (0.0, 5.0, 15.0, 45.0, 180.0)
FEET = joint_idx(FLOOR_JOINTS)
PELVIS = JOINT_INDEX["pelvis"]
WRISTS = joint_idx(("left_wrist", "right_wrist"))


@dataclass(frozen=True)
class HeldoutConfig:
    """Sample sizes and seed. ``edits`` is per set, over all held-out sources together
    (each source gets an equal share); the stress families get ``stress`` per set."""

    edits: int = 600
    stress: int = 300
    completions: int = 300  # per family (shared among sources likewise)
    recon: int = 3000  # held-out poses for the autoencoder round trip
    random_min: int = 2
    random_max: int = 6
    body_scale: float = 0.25  # bone factors 0.8 .. 1.25 (log-uniform)
    seed: int = 0
    chunk: int = 2048
    #: the start left where it was captured (the pelvis must travel too) instead of on
    #: the target's pelvis, as the issue's edits put it
    captured: bool = False
    #: every neural edit asks ``options.soft_ik`` (m; kept limbs ease into full stretch)
    soft_ik: float = 0.0


#: A seconds-long configuration for tests and smoke runs.
DEFAULT_DATASET = Path("data/poses.npz")
#: The stress family of the in-studio TEST split as captured (the held-out tables' peer).
STUDIO = "test: as captured"
QUICK = HeldoutConfig(edits=12, stress=6, completions=4, recon=50)


# --------------------------------------------------------------------------------------
# Edits in world space
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class WorldPairs:
    """N (start, target) poses in one world frame, the start on the target's pelvis."""

    start: F64  # [N, 21, 3]
    goal: F64  # [N, 21, 3]
    turn: F64  # [N] yaw between the two frames, degrees in [0, 180]
    rows: tuple[IntArray, IntArray]  # dataset rows of the start and the target frame

    def __len__(self) -> int:
        return int(self.start.shape[0])

    def edits(self, joint_sets: Sequence[IntArray]) -> Edits:
        joints = [np.asarray(j, dtype=np.intp) for j in joint_sets]
        return Edits(self.start, joints, [self.goal[i, j] for i, j in enumerate(joints)], self.goal)


def world_pairs(
    data: PoseDataset, world: F64, a: IntArray, b: IntArray, *, captured: bool = False
) -> WorldPairs:
    """Start = world pose of rows ``a`` moved onto the pelvis of rows ``b`` (``captured``:
    left where it was); goal = rows b."""
    onto = 0.0 if captured else (world[b, PELVIS] - world[a, PELVIS])[:, None, :]
    start = world[a] + onto
    yaw = np.asarray(data.yaw, dtype=np.float64)
    turn = np.degrees(np.abs(np.angle(np.exp(1j * (yaw[b] - yaw[a])))))
    return WorldPairs(start, world[b].copy(), turn, (a, b))


def rebodied(
    pairs: WorldPairs, rng: np.random.Generator, *, symmetric: bool, scale: float
) -> WorldPairs:
    """The same edits with each pair's body rebuilt (``core.bodies``): one random body
    per edit, the same for its start and target pose; the start is put back on the
    target's pelvis (or as far from it as before) and both are moved up or down together
    so that the target's lowest foot joint stays at its captured height."""
    bodies = random_bodies(rng, len(pairs), scale=scale, symmetric=symmetric)
    lengths = body_lengths(pairs.goal, bodies)
    goal = rebuild(pairs.goal, bodies, lengths)
    start = rebuild(pairs.start, bodies, lengths)
    away = pairs.start[:, PELVIS] - pairs.goal[:, PELVIS]  # 0 for the edits
    start += (goal[:, PELVIS] - start[:, PELVIS] + away)[:, None, :]
    lift = pairs.goal[:, FEET, 1].min(axis=1) - goal[:, FEET, 1].min(axis=1)
    up = np.zeros((len(pairs), 1, 3))
    up[:, 0, 1] = lift
    return WorldPairs(start + up, goal + up, pairs.turn, pairs.rows)


def edit_sets(
    engine: Engine,
    pairs: WorldPairs,
    random_pairs: WorldPairs,
    cfg: HeldoutConfig,
    rng: np.random.Generator,
) -> dict[str, Edits]:
    """Every solver single joint, both wrists, both ankles, the five end effectors (the
    same pairs) and random subsets of 2-6 solver joints (``random_pairs``; none where the
    models have fewer single-joint solvers than that, e.g. a 5-end-effector solver alone)."""
    pool = solver_joints(engine)
    n = len(pairs)
    sets: dict[str, Edits] = {j: pairs.edits([joint_idx((j,))] * n) for j in pool}
    for name, joints in PAIRS.items():
        sets[name] = pairs.edits([joint_idx(joints)] * n)
    sets[FIVE] = pairs.edits([joint_idx(END_EFFECTORS)] * n)
    hi = min(cfg.random_max, len(pool))
    if hi < cfg.random_min:  # too few single-joint solvers to draw subsets from
        return sets
    sizes = rng.integers(cfg.random_min, hi + 1, size=len(random_pairs))
    subsets = [
        np.sort(joint_idx([pool[int(k)] for k in rng.choice(len(pool), s, replace=False)]))
        for s in sizes
    ]
    sets[RANDOM_SET] = random_pairs.edits(subsets)
    return sets


# --------------------------------------------------------------------------------------
# Per-item results and their summaries
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Items:
    """Per-item metrics of one method on one set (cm; bone error relative)."""

    mpjpe: F64
    chain: F64
    reach: F64  # per target, flattened
    bone: F64
    turn: F64
    seconds: float

    @staticmethod
    def pool(parts: Sequence[Items]) -> Items:
        def cat(key: str) -> F64:
            return np.concatenate([getattr(p, key) for p in parts])

        return Items(
            cat("mpjpe"),
            cat("chain"),
            cat("reach"),
            cat("bone"),
            cat("turn"),
            seconds=sum(p.seconds for p in parts),
        )


@dataclass(frozen=True)
class MethodStats:
    n: int
    mpjpe: float
    mpjpe_median: float
    chain: float | None
    reach_mean: float
    reach_p95: float
    bone_max: float
    ms_per_edit: float

    @staticmethod
    def of(items: Items) -> MethodStats:
        chain = items.chain[np.isfinite(items.chain)]
        n = len(items.mpjpe)
        return MethodStats(
            n=n,
            mpjpe=float(items.mpjpe.mean()),
            mpjpe_median=float(np.median(items.mpjpe)),
            chain=float(chain.mean()) if chain.size else None,
            reach_mean=float(items.reach.mean()),
            reach_p95=float(np.percentile(items.reach, 95)),
            bone_max=float(items.bone.max()),
            ms_per_edit=items.seconds / max(n, 1) * 1e3,
        )


@dataclass(frozen=True)
class TurnRow:
    """MPJPE by method over the edits whose start and target differ by this much yaw."""

    bucket: str
    n: int
    mpjpe: dict[str, float]


@dataclass(frozen=True)
class Recon:
    """Autoencoder round trip (``Engine.reconstruct``) of real poses, cm."""

    n: int
    mean: float
    wrists: float  # mean error of both wrists
    worst_joint: str
    worst: float  # mean error of the worst joint
    per_joint: dict[str, float]


@dataclass(frozen=True)
class Family:
    """One edit family: a held-out source, all held-out sources, or a stress body."""

    name: str
    kind: str  # "holdout" | "stress"
    sources: list[str]
    clips: int
    frames: int
    sets: dict[str, dict[str, MethodStats]]  # set -> method -> stats
    turn_p50: float
    turn_p90: float
    by_turn: list[TurnRow]
    recon: Recon | None
    note: str = ""
    #: set -> method -> [mean, low, high] of its MPJPE minus FABRIK's on the same edits
    #: (cm; :func:`bench.metrics.paired_interval`, 95 %): whether a set's loss is real
    vs_fabrik: dict[str, dict[str, list[float]]] = field(default_factory=dict)


@dataclass
class HeldoutResults:
    config: dict[str, Any]
    families: list[Family] = field(default_factory=list)
    recon_available: bool = True
    seconds: dict[str, float] = field(default_factory=dict)
    models: dict[str, Any] = field(default_factory=dict)

    def family(self, name: str) -> Family:
        return next(f for f in self.families if f.name == name)

    def pooled(self) -> Family | None:
        """The held-out family of every source together (``<split>: all``), if run."""
        return next(
            (f for f in self.families if f.kind == "holdout" and f.name.endswith(": all")), None
        )

    def studio(self) -> Family | None:
        """The in-studio TEST split's world-space edits (:data:`STUDIO`), if run."""
        return next((f for f in self.families if f.name == STUDIO), None)

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @staticmethod
    def from_json(d: dict[str, Any]) -> HeldoutResults:
        """The results back from :meth:`to_json` (e.g. read from results.json)."""
        families = [
            Family(
                **{
                    **f,
                    "sets": {
                        s: {m: MethodStats(**v) for m, v in block.items()}
                        for s, block in f["sets"].items()
                    },
                    "by_turn": [TurnRow(**r) for r in f["by_turn"]],
                    "recon": None if f["recon"] is None else Recon(**f["recon"]),
                }
            )
            for f in d["families"]
        ]
        return HeldoutResults(**{**d, "families": families})


def _items(edits: Edits, poses: F64, turn: F64, seconds: float) -> Items:
    m = per_item(edits, poses)
    return Items(m["mpjpe"], m["chain"], m["reach"], m["bone"], turn, seconds)


def run_sets(
    engine: Engine, sets: dict[str, Edits], turn: dict[str, F64], chunk: int, soft_ik: float = 0.0
) -> dict[str, dict[str, Items]]:
    out: dict[str, dict[str, Items]] = {}
    for name, edits in sets.items():
        out[name] = {}
        for method in METHODS:
            t0 = time.perf_counter()
            poses = solve(engine, edits, method, chunk, soft_ik=soft_ik)
            out[name][method] = _items(edits, poses, turn[name], time.perf_counter() - t0)
    return out


def run_completion(engine: Engine, pairs: WorldPairs, chunk: int) -> dict[str, Items]:
    """The six base key points of the target pose: the start unchanged, FABRIK from the
    start onto them, and ``Engine.complete`` (``completion``: no bone lengths given, as in
    B2; ``completion_lengths``: given the target body's own bone lengths, as a user who
    has the character's skeleton can)."""
    key = joint_idx(BASE_KEYPOINTS)
    edits = pairs.edits([key] * len(pairs))
    out: dict[str, Items] = {}
    for method in ("identity", "fabrik"):
        t0 = time.perf_counter()
        poses = solve(engine, edits, method, chunk)
        out[method] = _items(edits, poses, pairs.turn, time.perf_counter() - t0)
    names = [JOINT_NAMES[c] for c in BONE_CHILDREN]
    for method, given in (("completion", False), ("completion_lengths", True)):
        t0 = time.perf_counter()
        done = [
            engine.complete(
                {name: goal[JOINT_INDEX[name]] for name in BASE_KEYPOINTS},
                dict(zip(names, bone_lengths(goal).tolist(), strict=True)) if given else None,
            ).pose
            for goal in pairs.goal
        ]
        poses = np.stack(done) if done else np.zeros((0, NUM_JOINTS, 3))
        out[method] = _items(edits, poses, pairs.turn, time.perf_counter() - t0)
    return out


def reconstruct(engine: Engine, poses: F64) -> F64 | None:
    """The autoencoder round trip of world poses, or None if this engine has none."""
    fn: Callable[[F64], F64] | None = getattr(engine, "reconstruct", None)
    if fn is None:
        return None
    return np.concatenate([fn(poses[s : s + 2048]) for s in range(0, len(poses), 2048)])


def recon_of(engine: Engine, poses: F64) -> Recon | None:
    out = reconstruct(engine, poses)
    if out is None or len(poses) == 0:
        return None
    err = np.linalg.norm(out - poses, axis=-1).mean(axis=0) * CM  # [21]
    worst = int(np.argmax(err))
    return Recon(
        n=len(poses),
        mean=float(err.mean()),
        wrists=float(err[WRISTS].mean()),
        worst_joint=JOINT_NAMES[worst],
        worst=float(err[worst]),
        per_joint={JOINT_NAMES[k]: float(v) for k, v in enumerate(err)},
    )


def by_turn(items: dict[str, dict[str, Items]]) -> list[TurnRow]:
    """MPJPE per method and turn bucket, over every edit set (completion excluded)."""
    rows = []
    for lo, hi in itertools.pairwise(TURN_EDGES):
        mpjpe: dict[str, float] = {}
        n = 0
        for method in METHODS:
            parts = [s[method] for name, s in items.items() if name != COMPLETION and method in s]
            turn = np.concatenate([p.turn for p in parts]) if parts else np.zeros(0)
            err = np.concatenate([p.mpjpe for p in parts]) if parts else np.zeros(0)
            sel = (turn >= lo) & ((turn < hi) | (hi == TURN_EDGES[-1]))
            n = int(sel.sum())
            if n:
                mpjpe[method] = float(err[sel].mean())
        rows.append(TurnRow(f"{lo:g}–{hi:g}°", n, mpjpe))
    return rows


def family(
    name: str,
    kind: str,
    data: PoseDataset,
    items: dict[str, dict[str, Items]],
    recon: Recon | None,
    turn: F64,
    note: str = "",
) -> Family:
    return Family(
        name=name,
        kind=kind,
        sources=sorted(set(data.clip_source[np.unique(data.clip)].tolist())),
        clips=len(np.unique(data.clip)),
        frames=len(data),
        sets={s: {m: MethodStats.of(v) for m, v in block.items()} for s, block in items.items()},
        turn_p50=float(np.percentile(turn, 50)) if turn.size else math.nan,
        turn_p90=float(np.percentile(turn, 90)) if turn.size else math.nan,
        by_turn=by_turn(items),
        recon=recon,
        note=note,
        vs_fabrik=versus_fabrik(items),
    )


def versus_fabrik(items: dict[str, dict[str, Items]]) -> dict[str, dict[str, list[float]]]:
    """Each edit set's neural MPJPE minus FABRIK's, edit by edit, with its interval."""
    return {
        name: {
            m: list(paired_interval(block[m].mpjpe, block["fabrik"].mpjpe))
            for m in ("neural_bone", "neural_exact")
            if m in block
        }
        for name, block in items.items()
        if name != COMPLETION and "fabrik" in block
    }


# --------------------------------------------------------------------------------------
# The run
# --------------------------------------------------------------------------------------
def _rng(seed: int, *stream: int) -> np.random.Generator:
    return np.random.default_rng([seed, *stream])


def recon_sample(world: F64, cfg: HeldoutConfig, k: int, n_sources: int) -> F64:
    """The poses of source ``k`` (of ``n_sources``) whose autoencoder round trip is scored:
    its share of ``cfg.recon``, drawn once per seed (``trainer.probe_directions`` scores
    the same poses)."""
    rows = _rng(cfg.seed, 12, k).choice(
        len(world), min(len(world), math.ceil(cfg.recon / n_sources)), replace=False
    )
    return world[np.sort(rows)]


def family_sets(
    engine: Engine,
    data: PoseDataset,
    world: F64,
    n: int,
    cfg: HeldoutConfig,
    rng: np.random.Generator,
    body: Callable[[WorldPairs], WorldPairs] | None = None,
) -> tuple[dict[str, Edits], dict[str, F64], WorldPairs]:
    """One family's edit sets, each set's turns, and its pairs (``body`` rebuilds the
    pairs as other bodies): what :func:`evaluate_family` scores."""
    pairs = world_pairs(data, world, *sample_pairs(data, n, rng), captured=cfg.captured)
    random_pairs = world_pairs(data, world, *sample_pairs(data, n, rng), captured=cfg.captured)
    if body is not None:
        pairs, random_pairs = body(pairs), body(random_pairs)
    sets = edit_sets(engine, pairs, random_pairs, cfg, rng)
    turn = {k: (random_pairs if k == RANDOM_SET else pairs).turn for k in sets}
    return sets, turn, pairs


def evaluate_family(
    engine: Engine,
    data: PoseDataset,
    world: F64,
    n: int,
    n_completion: int,
    cfg: HeldoutConfig,
    rng: np.random.Generator,
    body: Callable[[WorldPairs], WorldPairs] | None = None,
) -> tuple[dict[str, dict[str, Items]], WorldPairs]:
    """Every set and method of one family (``body`` rebuilds the pairs as other bodies)."""
    sets, turn, pairs = family_sets(engine, data, world, n, cfg, rng, body)
    items = run_sets(engine, sets, turn, cfg.chunk, cfg.soft_ik)
    m = min(n_completion, len(pairs))
    sub = WorldPairs(
        pairs.start[:m], pairs.goal[:m], pairs.turn[:m], (pairs.rows[0][:m], pairs.rows[1][:m])
    )
    items[COMPLETION] = run_completion(engine, sub, cfg.chunk)
    return items, pairs


def run_heldout(
    engine: Engine,
    dataset: PoseDataset,
    cfg: HeldoutConfig,
    *,
    split: str = "holdout",
    log: Callable[[str], None] = print,
) -> HeldoutResults:
    """Held-out families (one per source of ``split``, plus all pooled) and the stress
    families (the TEST split as captured, and rebuilt as symmetric / asymmetric bodies)."""
    res = HeldoutResults(config=dataclasses.asdict(cfg))
    t_all = time.perf_counter()
    held = dataset.subset(dataset.split_mask(split))
    if len(held) == 0:
        raise ValueError(f"the dataset has no {split!r} frames: no held-out bodies to test on")
    world = held.world()
    sources = sorted(set(held.clip_source[np.unique(held.clip)].tolist()))
    share = math.ceil(cfg.edits / len(sources))
    share_c = math.ceil(cfg.completions / len(sources))
    per_source: list[dict[str, dict[str, Items]]] = []
    recon_poses: list[F64] = []
    for k, source in enumerate(sources):
        t0 = time.perf_counter()
        mask = held.source_mask(source)
        data = held.subset(mask)
        items, pairs = evaluate_family(
            engine, data, world[mask], share, share_c, cfg, _rng(cfg.seed, 11, k)
        )
        poses = recon_sample(world[mask], cfg, k, len(sources))
        recon_poses.append(poses)
        fam = family(
            f"{split}: {source}", "holdout", data, items, recon_of(engine, poses), pairs.turn
        )
        res.families.append(fam)
        per_source.append(items)
        res.seconds[fam.name] = round(time.perf_counter() - t0, 1)
        log(_line(fam))
    pooled = {
        s: {m: Items.pool([src[s][m] for src in per_source]) for m in per_source[0][s]}
        for s in per_source[0]
    }
    turn = np.concatenate([p[FIVE]["identity"].turn for p in per_source])
    all_poses = np.concatenate(recon_poses)
    res.families.append(
        family(f"{split}: all", "holdout", held, pooled, recon_of(engine, all_poses), turn)
    )
    log(_line(res.families[-1]))
    res.recon_available = hasattr(engine, "reconstruct")

    test = dataset.subset(dataset.split_mask("test"))
    if len(test) == 0:
        log("no TEST frames: stress families skipped")
    else:
        test_world = test.world()
        variants: list[tuple[str, Callable[[WorldPairs], WorldPairs] | None, str]] = [
            (STUDIO, None, "in-studio TEST split, the same world-space edits"),
        ]
        for k, symmetric in enumerate((True, False)):
            what = "symmetric" if symmetric else "asymmetric"
            body_rng = _rng(cfg.seed, 21, k)

            def body(
                p: WorldPairs, sym: bool = symmetric, g: np.random.Generator = body_rng
            ) -> WorldPairs:
                return rebodied(p, g, symmetric=sym, scale=cfg.body_scale)

            variants.append(
                (
                    f"test: {what} bodies",
                    body,
                    f"TEST poses rebuilt with random {what} bone lengths "
                    f"(×{1 / (1 + cfg.body_scale):.2f}–{1 + cfg.body_scale:.2f} per bone) "
                    "and shifted pelvis/neck/head/collars",
                )
            )
        for k, (name, body_fn, note) in enumerate(variants):
            t0 = time.perf_counter()
            items, pairs = evaluate_family(
                engine,
                test,
                test_world,
                cfg.stress,
                cfg.completions,
                cfg,
                _rng(cfg.seed, 31, k),
                body_fn,
            )
            fam = family(
                name, "stress", test, items, recon_of(engine, pairs.goal), pairs.turn, note
            )
            res.families.append(fam)
            res.seconds[name] = round(time.perf_counter() - t0, 1)
            log(_line(fam))
    res.seconds["total"] = round(time.perf_counter() - t_all, 1)
    return res


def _line(fam: Family) -> str:
    five = fam.sets.get(FIVE, {})
    mp = ", ".join(f"{m} {s.mpjpe:.2f}" for m, s in five.items())
    recon = "–" if fam.recon is None else f"{fam.recon.mean:.2f}"
    return f"{fam.name}: 5 end effectors MPJPE {mp}; AE recon {recon} cm"


# --------------------------------------------------------------------------------------
# Compact console tables and the command line
# --------------------------------------------------------------------------------------
def _mean_over_sets(fam: Family, method: str) -> float | None:
    vals = [s[method].mpjpe for name, s in fam.sets.items() if name != COMPLETION and method in s]
    return float(np.mean(vals)) if vals else None


def print_tables(res: HeldoutResults) -> None:
    """Set x method MPJPE (pooled held-out) and one summary line per family."""
    from rich.console import Console
    from rich.table import Table

    def f(x: float | None) -> str:
        return "–" if x is None or not math.isfinite(x) else f"{x:.2f}"

    console = Console(width=None if Console().is_terminal else 150)
    pooled = res.pooled()
    if pooled is not None:
        table = Table(
            title=f"{pooled.name}: MPJPE to the real pose / reach (cm)",
            caption="6-point completion: the soft column is Engine.complete",
        )
        for col in ("set", "start", "FABRIK", "soft", "exact", "reach soft", "reach exact"):
            table.add_column(col, justify="left" if col == "set" else "right")
        for name, block in pooled.sets.items():
            soft = block.get("neural_bone") or block.get("completion")
            exact = block.get("neural_exact")
            table.add_row(
                name,
                *(f(block[m].mpjpe) if m in block else "–" for m in ("identity", "fabrik")),
                f(soft.mpjpe if soft else None),
                f(exact.mpjpe if exact else None),
                f(soft.reach_mean if soft else None),
                f(exact.reach_mean if exact else None),
            )
        console.print(table)
    table = Table(title="Families: MPJPE mean over edit sets (cm), completion, AE recon")
    for col in (
        "family", "n/set", "turn° p50/p90", "start", "FABRIK", "soft", "exact",
        "soft<FABRIK", "reach soft", "5 eff. soft/FABRIK", "6-pt", "AE (wrists)",
    ):  # fmt: skip
        table.add_column(col, justify="left" if col == "family" else "right")
    for fam in res.families:
        edit = {k: v for k, v in fam.sets.items() if k != COMPLETION}
        wins = sum(v["neural_bone"].mpjpe < v["fabrik"].mpjpe for v in edit.values())
        reach = np.mean([v["neural_bone"].reach_mean for v in edit.values()])
        five = edit.get(FIVE)
        ratio = None if five is None else five["neural_bone"].mpjpe / five["fabrik"].mpjpe
        compl = fam.sets.get(COMPLETION, {}).get("completion")
        recon = "–" if fam.recon is None else f"{fam.recon.mean:.2f} ({fam.recon.wrists:.2f})"
        n = next(iter(edit.values()))["identity"].n if edit else 0
        table.add_row(
            fam.name,
            str(n),
            f"{f(fam.turn_p50)}/{f(fam.turn_p90)}",
            *(f(_mean_over_sets(fam, m)) for m in METHODS),
            f"{wins}/{len(edit)}",
            f(float(reach)),
            f(ratio),
            f(compl.mpjpe if compl else None),
            recon,
        )
    console.print(table)
    if not res.recon_available:
        console.print("AE recon: this engine has no Engine.reconstruct (not measured)")


def overrides(pairs: Sequence[str]) -> dict[str, Any]:
    """``--serving`` pairs as settings: each value read as JSON (``3``, ``0.01``,
    ``true``), else kept as text (``completion``)."""
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise typer.BadParameter(f"{pair!r} is not KEY=VALUE", param_hint="--serving")
        try:
            out[key.strip()] = json.loads(text)
        except ValueError:
            out[key.strip()] = text
    return out


def engine_for(models: Path, serving: Sequence[str] | None, **kw: Any) -> Engine:
    """The engine of ``models`` with the ``--serving`` pairs ``serving`` (:func:`overrides`),
    its refusals as the command line's errors: a models folder not as its manifest says
    (``--models``), a setting unknown, fixed by training or out of range (``--serving``)."""
    from core.manifest import ManifestError

    asked = overrides(serving or [])
    try:
        return Engine(models, serving=asked, **kw)
    except ManifestError as exc:  # a file missing or not the one the manifest names
        raise typer.BadParameter(str(exc), param_hint="--models") from None
    except ValidationError as exc:  # out of range, or not of the setting's type
        where = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        raise typer.BadParameter(where, param_hint="--serving") from None
    except ValueError as exc:  # not a setting, or fixed by training
        raise typer.BadParameter(str(exc), param_hint="--serving") from None


def main(
    models: Annotated[Path, typer.Option(help="Models folder (manifest.json).")] = Path("models"),
    dataset: Annotated[Path, typer.Option(help="Dataset file (format 2).")] = DEFAULT_DATASET,
    out: Annotated[Optional[Path], typer.Option(help="Write the results (JSON) here.")] = None,  # noqa: UP045
    quick: Annotated[bool, typer.Option(help="A handful of edits per set (smoke run).")] = False,
    seed: Annotated[int, typer.Option(help="Seed of every sample.")] = 0,
    split: Annotated[str, typer.Option(help="Split of the held-out bodies.")] = "holdout",
    serving: Annotated[
        Optional[list[str]],  # noqa: UP045
        typer.Option(
            metavar="KEY=VALUE",
            help="Serve with this setting of the manifest's serving block instead (repeat "
            "for more; e.g. passes=3, keep_pelvis=0.01, turn_critic=autoencoder).",
        ),
    ] = None,
    captured: Annotated[
        bool,
        typer.Option(help="Starts left where captured, not on the target's pelvis."),
    ] = False,
    soft_ik: Annotated[
        float,
        typer.Option(min=0.0, max=SOFT_IK_MAX, help="Every neural edit asks options.soft_ik (m)."),
    ] = 0.0,
) -> None:
    """Held-out bodies and the stress set only, against any models folder."""
    from rich.console import Console

    from trainer.data.dataset import SPLITS, DatasetError, load_dataset

    if not (models / "manifest.json").is_file():
        raise typer.BadParameter(f"no manifest.json in {models}", param_hint="--models")
    if not dataset.is_file():
        raise typer.BadParameter(f"no dataset file at {dataset}", param_hint="--dataset")
    console = Console(stderr=True)
    cfg = dataclasses.replace(
        QUICK if quick else HeldoutConfig(), seed=seed, captured=captured, soft_ik=soft_ik
    )
    engine = engine_for(models, serving, threads=1)
    try:
        data = load_dataset(dataset)
    except DatasetError as exc:
        raise typer.BadParameter(str(exc), param_hint="--dataset") from None
    try:
        present = bool(data.split_mask(split).any())
    except ValueError as exc:  # not a split name
        raise typer.BadParameter(str(exc), param_hint="--split") from None
    if not present:  # (a studio's dataset has no held-out bodies)
        have = [s for s in SPLITS if s != split and data.split_mask(s).any()]
        raise typer.BadParameter(
            f"{dataset} has no {split!r} frames: no bodies to test on; another split "
            f"({', '.join(f'--split {s}' for s in have) or 'none has frames'}) or a dataset "
            "whose maps hold bodies out (docs/data.md)",
            param_hint="--split",
        )
    res = run_heldout(engine, data, cfg, split=split, log=console.log)
    res.models = {
        "dir": str(models), "version": engine.version, "overrides": overrides(serving or []),
        **engine.serving.model_dump(mode="json"),
    }  # fmt: skip
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(out, (json.dumps(res.to_json(), indent=1) + "\n").encode())
        console.log(f"wrote {out}")
    print_tables(res)


if __name__ == "__main__":
    typer.run(main)
