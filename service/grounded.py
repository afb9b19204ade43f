"""A character's feet kept over the floor, as the canonical answer keeps them.

The engine's answer crouches a body whose pelvis is lowered with its feet over the floor
(README), and the pose form answers it so. A character's answer is that answer laid onto
its own skeleton (``core.retarget``): the pelvis's joint is fitted onto the solved pelvis
and hips, its hips weighing most, and where the networks drew the pelvis triangle other
than the character's (Mixamo's hips are level with the pelvis), the fit left the pelvis a
few centimetres off; the polish that then met a pelvis target carried the legs down with
the body. The docs' character, its pelvis lowered 20 cm, came back with both ankles 6 cm
under the floor (3.7 cm in exact reach), the Bandai-Namco walk's 5 cm, where the pose form
of the same points keeps them on it (an API audit, 2026-12-07).

Where the answer lays an ankle or a toe under the floor lower than the canonical answer
did, it is laid again with the canonical answer's ankles and toes held where it put them
(as pins, but for those a request targets or pins itself), and kept where it meets the
targets no worse."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from core.characters import F64
from core.retarget import Retargeted
from core.skeleton import JOINT_INDEX
from service.problems import SolveProblem

#: the canonical points a body stands on: its ankles and toes
FEET = tuple(JOINT_INDEX[n] for n in ("left_ankle", "right_ankle", "left_foot", "right_foot"))

Pairs = Sequence[tuple[int, F64]]


def grounded(
    to_service: Callable[[F64], F64],
    p: SolveProblem,
    solved: F64,
    targets: Pairs,
    pins: Pairs,
    fit: Callable[[Pairs], Retargeted],
) -> Retargeted:
    """``fit(pins)``, or ``fit`` again with the canonical answer's (``solved``: the 21
    points, character units) feet held too, where the first lays one under the floor
    (``p.floor``, metres, the service's +Y: ``to_service``) lower than ``solved`` has it,
    each by more than the tolerance, and the second meets ``targets`` no worse."""
    out = fit(pins)
    tol = p.tolerance
    now, meant = to_service(out.points)[:, 1], to_service(solved)[:, 1]
    own = {j for j, _ in targets} | {j for j, _ in pins}
    low = [j for j in FEET if j not in own and now[j] < min(p.floor, meant[j]) - tol]
    if not low:
        return out
    held = [(j, solved[j]) for j in FEET if j not in own]
    again = fit(sorted([*pins, *held], key=lambda pin: pin[0]))
    if _miss(to_service, again, targets) <= _miss(to_service, out, targets) + tol:
        return again
    return out


def _miss(to_service: Callable[[F64], F64], out: Retargeted, targets: Pairs) -> float:
    """The farthest of ``targets`` (metres) from its point in ``out``; 0 for none."""
    if not targets:
        return 0.0
    goals = to_service(np.asarray([g for _, g in targets], dtype=np.float64))
    points = to_service(out.points[[j for j, _ in targets]])
    return float(np.linalg.norm(points - goals, axis=1).max())
