"""Turn search: a many-target edit may ask for the body to face another way.

The solvers were trained on pairs whose goal faces the start's way (docs/generalisation.md
item 1), so when the targets of an edit were taken from a body that has turned (a user
dragging the head, both hands and both feet round), the network bends the body towards
them instead of turning it: on held-out 5-end-effector edits whose two frames are more
than 45° apart its answer is worse than FABRIK's (11.7 against 10.4 cm). Here, before the
edit is solved, its start pose is tried turned about the vertical through its pelvis by
``turn_yaws`` evenly spaced yaws (0 first); each candidate is solved as a soft edit (the
item's passes, bone pass, carry) and the one whose answer scores lowest is kept: the mean
distance of its targets, plus ``turn_plausibility`` times the mean distance of the answer
to what ``turn_critic`` makes of it: the autoencoder's round trip of it, or the body
completion level 1 builds from the answer's own base key points (pelvis, neck, wrists,
ankles): a body bent towards targets it should have turned to is far from the body those
points imply (docs/generalisation.md items 22, 24), the unturned start winning unless
another scores at least ``turn_margin`` metres lower. The edit is then solved as asked
from the kept start. Only neural items with at least ``turn_min_targets`` targets and no
pins take part (``options.turn_search: false`` opts out): fewer targets say little about a
facing, and pins ask for joints to stay where they are.

Every candidate is an item of one batch solve, so the cost is about ``turn_yaws`` + 1
solves per searching item; answers stay bit-identical (each item alone, argmin ties to the
unturned start). The answer's solver path ends with ``turn <deg>`` where the start turned.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from core.manifest import Serving
from core.skeleton import JOINT_INDEX
from service.problems import BatchAnswer, _Items

if TYPE_CHECKING:  # pragma: no cover
    from service.engine import Engine

F64 = npt.NDArray[np.float64]
_PELVIS = JOINT_INDEX["pelvis"]


@dataclass(frozen=True)
class TurnSearch:
    """An engine's turn search: ``yaws`` candidate turns (1: off) for neural items with at
    least ``min_targets`` targets and no pins, the unturned start kept unless another
    scores ``margin`` metres lower (``plausibility``: the weight in the score of the
    answer's distance to what ``critic`` makes of it, "autoencoder" or "completion"). Read
    from a manifest's ``serving`` block
    (:meth:`of`), which defines the settings and their defaults."""

    yaws: int
    margin: float
    min_targets: int
    plausibility: float
    critic: Literal["autoencoder", "completion"]

    @staticmethod
    def of(serving: Serving, yaws: int | None = None) -> TurnSearch:
        """The search ``serving`` asks for (``yaws``: an override, e.g. 1 for none)."""
        return TurnSearch(
            serving.turn_yaws if yaws is None else int(yaws), serving.turn_margin,
            serving.turn_min_targets, serving.turn_plausibility, serving.turn_critic,
        )  # fmt: skip

    def searches(
        self, method: str, n_targets: int, pinned: bool, wanted: bool | None = None
    ) -> bool:
        """Whether an item searches (``wanted``: its ``options.turn_search``; None: yes)."""
        return (
            wanted is not False and self.yaws > 1 and method != "fabrik" and not pinned
            and n_targets >= self.min_targets
        )  # fmt: skip

    def factor(self, method: str, n_targets: int, pinned: bool, wanted: bool | None = None) -> int:
        """The solves an item costs per pass: its candidates and itself, or 1."""
        return self.yaws + 1 if self.searches(method, n_targets, pinned, wanted) else 1


#: No search (models without ``serving.turn_*``, FABRIK-only callers).
NO_SEARCH = TurnSearch.of(Serving())


def searching(engine: Engine, items: _Items) -> npt.NDArray[np.intp]:
    """The items that search: neural, enough targets, no pins (none if the search is off)."""
    t = engine.turn_search
    if t.yaws <= 1:
        return np.zeros(0, dtype=np.intp)
    ok = items.turn & ~items.fab & (items.n_t >= t.min_targets) & (items.cnt == items.n_t)
    return np.flatnonzero(ok)


def turned(poses: F64, yaw: float) -> F64:
    """``poses [N, 21, 3]`` (world, +Y up) turned by ``yaw`` radians about the vertical
    through each pose's pelvis."""
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    pelvis = poses[:, _PELVIS : _PELVIS + 1]
    out: F64 = (poses - pelvis) @ rot.T + pelvis
    return out


def search(
    engine: Engine, items: _Items, reps: npt.NDArray[np.int64],
    solve: Callable[[_Items, npt.NDArray[np.int64]], BatchAnswer],
) -> tuple[_Items, npt.NDArray[np.int64]]:  # fmt: skip
    """``items`` with the start of every searching item turned as the search chose, and
    each item's turn in whole degrees (0: not turned). ``solve(items, reps)`` solves a
    batch (the engine's own path)."""
    sel = searching(engine, items)
    degrees = np.zeros(len(items.poses), dtype=np.int64)
    if sel.size == 0:
        return items, degrees
    y, m = engine.turn_search.yaws, sel.size
    yaws = 2.0 * np.pi * np.arange(y) / y
    starts = items.poses[sel]
    candidates = np.concatenate([turned(starts, float(a)) if a else starts for a in yaws])
    rep = np.tile(sel, y)
    soft = dataclasses.replace(items.soft(rep, items.poses), poses=candidates)
    ans = solve(soft, reps[rep])
    score = (ans.errors * soft.targets()).sum(axis=1) / soft.n_t
    if engine.turn_search.plausibility > 0:  # how unlike a real body the answer is
        score += engine.turn_search.plausibility * implausibility(engine, ans.pose, soft.floors)
    score = score.reshape(y, m)
    score[0] -= engine.turn_search.margin
    best = np.argmin(score, axis=0)  # ties: the first, the unturned start
    poses = items.poses.copy()
    poses[sel] = candidates.reshape(y, m, *starts.shape[1:])[best, np.arange(m)]
    deg = np.rint(np.degrees(yaws[best])).astype(np.int64)
    degrees[sel] = np.where(deg > 180, deg - 360, deg)
    return dataclasses.replace(items, poses=poses), degrees


def implausibility(engine: Engine, poses: npt.NDArray[np.floating], floors: F64) -> F64:
    """Mean per-joint distance (m) of world ``poses [N, 21, 3]`` (over ``floors [N]``) to
    what the search's critic makes of them: small for poses like the training ones."""
    world = np.asarray(poses, dtype=np.float64).copy()
    other: npt.NDArray[np.floating]
    if engine.turn_search.critic == "completion":
        world[:, :, [0, 2]] -= world[:, _PELVIS : _PELVIS + 1, [0, 2]]
        world[:, :, 1] -= floors[:, None]
        other = engine.implied_bodies(world)
    else:
        world[:, :, 1] -= floors[:, None]
        other = engine.reconstruct(world)
    out: F64 = np.linalg.norm(other - world, axis=-1).mean(axis=-1)
    return out


def mark(ans: BatchAnswer, degrees: npt.NDArray[np.int64]) -> BatchAnswer:
    """``ans`` with ``turn <deg>`` at the end of the solver path of every turned item."""
    if not degrees.any():
        return ans
    keys = [(int(p), int(d)) for p, d in zip(ans.path_of.tolist(), degrees.tolist(), strict=True)]
    distinct = list(dict.fromkeys(keys))
    paths = tuple(
        ans.paths[p] + ((f"turn {d}",) if d else ()) for p, d in distinct
    )  # fmt: skip
    index = {k: i for i, k in enumerate(distinct)}
    path_of = np.fromiter((index[k] for k in keys), np.int64, len(keys))
    return dataclasses.replace(ans, paths=paths, path_of=path_of)
