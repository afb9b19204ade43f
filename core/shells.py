"""Where the root of a FABRIK solve may lie so that its anchors stay within reach.

An anchor is a pin (or, without pins, a target already reached at the start). Its chain
from the root (pelvis) reaches between an inner radius (as near as the chain folds: its
longest bone against the rest) and an outer one (1 % short of full stretch): a shell
around the anchor. A free root is pulled back into every shell each iteration
(:func:`clamp_root`); a fixed root that the networks moved out of one is moved, with the
whole start, into them first (:func:`onto_pins`). Arrays are :mod:`core.kinematics`'s
internal layout, ``[k, 3, N]`` (N = flattened batch); ``core.compiled_fabrik`` has the
same steps per item in machine code.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]
BoolArray = npt.NDArray[np.bool_]

#: Distance (metres) at or below which a direction is undefined: in effect only exact
#: coincidence, the same test as the fast paths' "1 / distance is not finite".
TINY = 1e-300


def pin_mask(pinned: object, k: int) -> BoolArray | None:
    """``pinned`` (K booleans, or None) as an array; ``ValueError`` if not K of them."""
    mask = None if pinned is None else np.asarray(pinned, dtype=bool).reshape(-1)
    if mask is not None and mask.shape != (k,):
        raise ValueError(f"pinned must be {k} booleans (one per target), got {mask.shape}")
    return mask


def norm3(v: F64) -> F64:
    """Euclidean norm over axis 1 of ``[k, 3, N]`` -> ``[k, N]``."""
    out: F64 = np.sqrt(np.add.reduce(v * v, axis=1))
    return out


def dot3(a: F64, b: F64) -> F64:
    out: F64 = np.add.reduce(a * b, axis=1)
    return out


@dataclass(frozen=True)
class Shells:
    """Where the root may lie: around each anchor target, between ``inner`` and ``radii``."""

    start: F64  # [3, N] root at the start of the solve
    tpos: F64  # [K, 3, N]
    radii: F64  # [K, N]
    inner: F64  # [K, N]
    anchors: BoolArray  # [K, N]


def clamp_root(proposal: F64, clamp: Shells) -> F64:
    """Pull the proposed root (``[3, N]``) back along the segment from the start until
    every anchor target stays within its chain's reach: ``|root - target| <= radius``;
    then into every anchor's shell (:func:`project_root`)."""
    start, tpos, radii = clamp.start, clamp.tpos, clamp.radii
    d = proposal - start
    e = start - tpos  # [K, 3, N]
    dd = (d * d).sum(axis=0)  # [N]
    ed = dot3(e, d[None])  # [K, N]
    ee = dot3(e, e)
    disc = np.maximum(ed * ed - dd * (ee - radii * radii), 0.0)
    moving = dd > TINY * TINY
    s = (np.sqrt(disc) - ed) / np.where(moving, dd, 1.0)
    s = np.where(clamp.anchors & moving, np.clip(s, 0.0, 1.0), 1.0)
    out: F64 = start + d * s.min(axis=0, initial=1.0)
    return project_root(out, clamp)


def project_root(root: F64, clamp: Shells, rounds: int = 32) -> F64:
    """``root`` ``[3, N]`` into every anchor's shell (between its ``inner`` and outer
    radius) by alternating projections (a no-op inside)."""
    tpos, radii, inner, anchors = clamp.tpos, clamp.radii, clamp.inner, clamp.anchors
    for _ in range(rounds):
        n = norm3(root[None] - tpos)
        off = anchors & ((n > radii * (1.0 + 1e-9)) | (n < inner * (1.0 - 1e-9)))
        if not off.any():
            break
        for k in np.flatnonzero(off.any(axis=1)).tolist():
            dk = root - tpos[k]
            nk = np.maximum(norm3(dk[None])[0], TINY)
            fix = anchors[k] & ((nk > radii[k] * (1.0 + 1e-9)) | (nk < inner[k] * (1.0 - 1e-9)))
            to = np.minimum(np.maximum(nk, inner[k]), radii[k])
            root = np.where(fix[None], tpos[k] + dk * (to / nk)[None], root)
    return root


def shells(path: F64, lens: F64, root: F64, tpos: F64, anchors: BoolArray, cap: bool) -> Shells:
    """Where the root may lie for each anchor's chain (``path`` ``[K, 20]`` bones of each
    target's chain, ``lens`` ``[20, N]``): 1 % short of full stretch, so pinned limbs never
    lock straight (FABRIK crawls at full stretch), or at the start's own distance if
    farther (``cap``, pins: never beyond full stretch); no nearer than the chain folds
    (its longest bone against the rest: a lone bone is a sphere)."""
    reach = path @ lens
    inner = np.maximum(2.0 * np.max(path[:, :, None] * lens[None], axis=1) - reach, 0.0)
    dist = norm3(root[None] - tpos)
    if cap:
        dist = np.minimum(dist, reach)
    radii = np.maximum(np.maximum(0.99 * reach, dist), inner)
    return Shells(root, tpos, radii, inner, anchors)


def onto_pins(x0: F64, where: Shells) -> F64:
    """A start whose root stays put but lies out of a pin's reach (the networks moved the
    body off its pins), moved whole the least way that brings every pin within it;
    unchanged otherwise."""
    out: F64 = x0 + (project_root(x0[0], where) - x0[0])[None]
    return out


def above_pins(
    targeted: IntArray, ranks: IntArray, path: F64, hold: BoolArray
) -> list[tuple[int, int, int, list[int]]]:
    """(index into ``targeted``, rank, its first target, the pins below it) of every targeted
    joint other than the root, not itself pinned, with pins below it (``ranks`` of the K
    targets, ``path`` their ``[K, 20]`` chains from the root): what :func:`hold_targets`
    holds, the same for every iteration of a solve."""
    out = []
    for i, r in enumerate(targeted.tolist()):
        mine = np.flatnonzero(ranks == r)
        if r == 0 or hold[mine].any():
            continue
        kt = int(mine[0])
        below = [kp for kp in np.flatnonzero(hold).tolist()
                 if ranks[kp] != r and bool(np.all(path[kp] >= path[kt]))]  # fmt: skip
        if below:
            out.append((i, r, kt, below))
    return out


def hold_targets(
    proposal: F64, aim: F64, above: list[tuple[int, int, int, list[int]]], path: F64,
    lens: F64, tpos: F64, root: F64,
) -> None:  # fmt: skip
    """In place, every iteration: each targeted joint above pins (:func:`above_pins`) has its
    proposal moved towards its target (``aim[i]`` for ``targeted[i]``) into each such pin's
    shell (the chain between them) and its own chain's from the ``root`` where it is now: a
    pinned wrist keeps a dragged elbow on the sphere of its forearm, a dragged chest stays
    within both arms' reach of pinned hands, at a point its spine can bring it to. The
    target is approached as far as the pins allow (the root's own target:
    :func:`clamp_root`). The projections start from the proposal of the iteration before
    (the target at first), the root's shell first and the pins' last: a lone bone's shell
    is a sphere, which alternating projections approach slowly where it barely meets the
    root's, so each iteration goes on where the last one stopped."""
    for i, r, kt, below in above:
        chains = np.concatenate([path[kt][None], path[below] - path[kt]])
        centres = np.concatenate([root[None], tpos[below]])
        where = shells(chains, lens, aim[i], centres,
                       np.ones((len(below) + 1, 1), dtype=np.bool_), True)  # fmt: skip
        proposal[r] = project_root(proposal[r], where)
