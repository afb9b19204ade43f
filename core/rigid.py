"""The two rigid pairs of a body: the hips on the pelvis, the collars on the chest.

In every skeleton our data comes from, the two hips hang from the pelvis's joint at fixed
offsets, and the two collars from one chest joint: the width between the hips, and
between the collars, never changes within a clip (to 0.01 cm in all six sources,
``data/poses.npz``), while the spine and the neck bend between them. The canonical
skeleton has a bone from the pelvis to each hip and from the chest (spine2) to each
collar, each free to turn, and the networks place those joints themselves: on bodies
they never saw they squeezed a body's hips together (docs/generalisation-serving-2.md
item 45: on exact and soft edits of five studios' files, 12 of 100 answers without pins
had the hips closer than 80 % of the body's width, down to 26 %). A character's own
skeleton cannot follow that (its pelvis is one joint), so its answer then moved far from
the canonical one.

:func:`keep_pairs` turns each pair the answer squeezed (:data:`SQUEEZED`), after the bone
pass, to the angle the two bones make in the start pose, as one rigid part: the pair's
frame (across: from the right joint to the left; up: their bisector without its across
part) goes where the answer's frame is, so the pair faces as the networks put it. Bone
lengths are the answer's (the bone pass's); every joint below a moved hip or collar moves
with it, so the legs and arms keep their bones and directions. A pair whose directions are
degenerate (a zero-length bone, the two parallel) is left as it is.

Batched numpy over ``[..., 21, 3]``: the reference the compiled kernel
(:func:`keep_pairs_item`, in ``core.compiled.unscale``) is held to in tests.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from core.geometry import perpendicular
from core.jit import jit
from core.skeleton import JOINT_INDEX, NUM_JOINTS, SUBTREE

F64 = npt.NDArray[np.float64]
Bool = npt.NDArray[np.bool_]

#: (top, left, right) of each rigid pair
PAIRS: npt.NDArray[np.int64] = np.array(
    [
        [JOINT_INDEX["pelvis"], JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]],
        [JOINT_INDEX["spine2"], JOINT_INDEX["left_collar"], JOINT_INDEX["right_collar"]],
    ],
    dtype=np.int64,
)
#: A direction or frame axis this short is undefined (the pair is left as it is).
TINY = 1e-12
#: A pair whose two joints lie nearer each other than this share of their distance in the
#: start is squeezed: only such a pair is turned back (a turn of every pair, item 65 of
#: docs/generalisation-3.md, moved the arms and legs hung from it with every small change
#: of the networks' pair: jumps between frames of cleaned clips 65 -> 93 in exact reach).
SQUEEZED = 0.8


def _frames(a: F64, b: F64) -> tuple[F64, Bool]:
    """Rows ``[..., 3, 3]``: unit(a - b), unit((a + b) without that), their cross; and
    where they are defined. Where ``a`` and ``b`` point apart on one line (a pair drawn
    straight across its top, as some skeletons' hips are: ``a + b`` is 0 without its part
    along the first row), the second row is the axis least along the first without that
    part: any row across serves, as ``a`` and ``b`` then lie along the first."""
    x = a - b
    nx = np.linalg.norm(x, axis=-1, keepdims=True)
    x = x / np.where(nx > TINY, nx, 1.0)
    y = a + b
    y = y - np.sum(y * x, axis=-1, keepdims=True) * x
    ny = np.linalg.norm(y, axis=-1, keepdims=True)
    y = np.where(ny > TINY, y, perpendicular(x))
    ny = np.linalg.norm(y, axis=-1, keepdims=True)
    y = y / np.where(ny > TINY, ny, 1.0)
    ok = (nx[..., 0] > TINY) & (ny[..., 0] > TINY)
    return np.stack([x, y, np.cross(x, y)], axis=-2), ok


def keep_pairs(positions: npt.ArrayLike, reference: npt.ArrayLike) -> F64:
    """``positions`` ``[..., 21, 3]`` with each pair of :data:`PAIRS` :data:`SQUEEZED`
    turned to the angle it makes in ``reference`` (broadcastable; the start pose), subtrees
    carried."""
    out = np.array(positions, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    for top, left, right in PAIRS:
        a, b = ref[..., left, :] - ref[..., top, :], ref[..., right, :] - ref[..., top, :]
        la = np.linalg.norm(a, axis=-1, keepdims=True)
        lb = np.linalg.norm(b, axis=-1, keepdims=True)
        c, d = out[..., left, :] - out[..., top, :], out[..., right, :] - out[..., top, :]
        lc = np.linalg.norm(c, axis=-1, keepdims=True)
        ld = np.linalg.norm(d, axis=-1, keepdims=True)
        lens_ok = ((la > TINY) & (lb > TINY) & (lc > TINY) & (ld > TINY))[..., 0]
        lens_ok &= np.linalg.norm(c - d, axis=-1) < SQUEEZED * np.linalg.norm(a - b, axis=-1)
        a, b = a / np.where(la > TINY, la, 1.0), b / np.where(lb > TINY, lb, 1.0)
        c, d = c / np.where(lc > TINY, lc, 1.0), d / np.where(ld > TINY, ld, 1.0)
        f_ref, ok_ref = _frames(a, b)
        f_out, ok_out = _frames(c, d)
        ok = lens_ok & ok_ref & ok_out
        turn = np.swapaxes(f_out, -1, -2) @ f_ref  # reference frame -> answer frame
        for joint, v, n in ((left, a, lc), (right, b, ld)):
            u = (turn @ v[..., :, None])[..., 0]
            move = out[..., top, :] + n * u - out[..., joint, :]
            move = np.where(ok[..., None], move, 0.0)
            out[..., SUBTREE[joint], :] += move[..., None, :]
    return out


@jit
def _frame_into(a: F64, b: F64, out: F64) -> bool:  # pragma: no cover - compiled
    """:func:`_frames` for one pair of unit vectors, into ``out [3, 3]``."""
    x0, x1, x2 = a[0] - b[0], a[1] - b[1], a[2] - b[2]
    nx = np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if nx <= TINY:
        return False
    x0, x1, x2 = x0 / nx, x1 / nx, x2 / nx
    y0, y1, y2 = a[0] + b[0], a[1] + b[1], a[2] + b[2]
    s = y0 * x0 + y1 * x1 + y2 * x2
    y0, y1, y2 = y0 - s * x0, y1 - s * x1, y2 - s * x2
    ny = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    if ny <= TINY:  # a and b apart on one line: the axis least along x, without x
        k = 0
        if abs(x1) < abs(x0):
            k = 1
        if abs(x2) < abs(x0 if k == 0 else x1):
            k = 2
        e0 = 1.0 if k == 0 else 0.0
        e1 = 1.0 if k == 1 else 0.0
        e2 = 1.0 if k == 2 else 0.0
        s = e0 * x0 + e1 * x1 + e2 * x2
        y0, y1, y2 = e0 - s * x0, e1 - s * x1, e2 - s * x2
        ny = np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
        if ny <= TINY:
            return False
    y0, y1, y2 = y0 / ny, y1 / ny, y2 / ny
    out[0, 0], out[0, 1], out[0, 2] = x0, x1, x2
    out[1, 0], out[1, 1], out[1, 2] = y0, y1, y2
    out[2, 0], out[2, 1], out[2, 2] = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    return True


@jit
def _unit3(out: F64, j: int, top: int, v: F64) -> float:  # pragma: no cover - compiled
    """``v`` = unit(out[j] - out[top]); returns the length (0 where undefined)."""
    for i in range(3):
        v[i] = out[j, i] - out[top, i]
    n = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    if n <= TINY:
        return 0.0
    for i in range(3):
        v[i] = v[i] / n
    return float(n)


@jit
def keep_pairs_item(out: F64, ref: F64) -> None:  # pragma: no cover - compiled
    """:func:`keep_pairs` of one pose ``out [21, 3]`` in place (``ref [21, 3]``)."""
    a, b, c, d = np.empty(3), np.empty(3), np.empty(3), np.empty(3)
    f_ref, f_out = np.empty((3, 3)), np.empty((3, 3))
    for p in range(PAIRS.shape[0]):
        top, left, right = PAIRS[p, 0], PAIRS[p, 1], PAIRS[p, 2]
        la, lb = _unit3(ref, left, top, a), _unit3(ref, right, top, b)
        lc, ld = _unit3(out, left, top, c), _unit3(out, right, top, d)
        if la == 0.0 or lb == 0.0 or lc == 0.0 or ld == 0.0:
            continue
        w_ref = w_out = 0.0
        for i in range(3):
            w_ref += (ref[left, i] - ref[right, i]) ** 2
            w_out += (out[left, i] - out[right, i]) ** 2
        if not np.sqrt(w_out) < SQUEEZED * np.sqrt(w_ref):
            continue
        if not (_frame_into(a, b, f_ref) and _frame_into(c, d, f_out)):
            continue
        for side in range(2):
            joint, v, n = (left, a, lc) if side == 0 else (right, b, ld)
            move = np.empty(3)
            for i in range(3):
                u = 0.0
                for k in range(3):  # (f_out^T f_ref) v, in the numpy reference's order
                    t = f_out[0, i] * f_ref[0, k] + f_out[1, i] * f_ref[1, k]
                    u += (t + f_out[2, i] * f_ref[2, k]) * v[k]
                move[i] = out[top, i] + n * u - out[joint, i]
            for k in range(NUM_JOINTS):
                if SUBTREE[joint, k]:
                    for i in range(3):
                        out[k, i] = out[k, i] + move[i]
