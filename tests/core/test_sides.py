"""core.sides on real poses: every body the right way round scores well above the line,
the same bodies with their sides swapped well below it, whatever way they face."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from core.sides import REST_DECIDES, SWAPPED_BELOW, facing_score, mirrored
from core.skeleton import JOINT_INDEX as J
from core.skeleton import MIRROR
from tests.conftest import PosePairs


def test_real_poses_score_as_bodies_and_their_swapped_sides_as_the_opposite(
    real_poses: PosePairs,
) -> None:
    """The real poses (Bandai-Namco and CMU dance, metres), each under a seeded yaw and a
    scale: a swapped pose scores minus its own (to rounding); no pose alone is called
    swapped, every swapped one is with a rest that says nothing (0); a rest that says which
    side is which decides every frame, whatever the frame says."""
    rng = np.random.default_rng(0)
    poses = real_poses.poses
    turn = Rotation.from_euler("y", rng.uniform(-np.pi, np.pi, (len(poses), 1))).as_matrix()
    turned = np.einsum("nij,nkj->nki", turn, poses) * rng.uniform(0.5, 50.0, (len(poses), 1, 1))
    own, other = facing_score(turned), facing_score(turned[:, list(MIRROR)])
    assert len(poses) > 1000 and np.allclose(other, -own, atol=1e-12)
    assert np.median(own) > 1.0 and own.min() > SWAPPED_BELOW, np.sort(own)[:5]
    blank = np.zeros((21, 3))  # a rest pose with no extent: no facing, scores 0
    assert facing_score(blank) == 0.0
    rest, swapped = turned[0], turned[0, list(MIRROR)]  # a real pose as a rest: +1 or more
    assert facing_score(rest) > REST_DECIDES
    for k in range(0, len(poses), 97):
        assert mirrored(blank, turned[k]) is None
        said = mirrored(blank, turned[k, list(MIRROR)])
        assert said == "this frame, its rest pose saying nothing"
        assert mirrored(rest, turned[k, list(MIRROR)]) is None  # the rest decides
        assert mirrored(swapped, turned[k]) == "its rest pose"


def test_legs_that_say_nothing_score_nothing() -> None:
    """A standing rest with straight legs and toes straight below the ankles (a rig with
    no toe joint mapped apart) scores 0, and so does one whose hips and shoulders give no
    facing; toes ahead score +1, behind -1."""
    rest = np.zeros((21, 3))
    for side, x in (("left", 0.1), ("right", -0.1)):  # facing +Z: left is +X
        for joint, y in (("hip", 0.9), ("knee", 0.5), ("ankle", 0.1), ("foot", 0.0)):
            rest[J[f"{side}_{joint}"]] = [x, y, 0.0]
        rest[J[f"{side}_shoulder"]] = [2 * x, 1.4, 0.0]
    assert facing_score(rest) == 0.0
    ahead, behind = rest.copy(), rest.copy()
    for side in ("left", "right"):
        ahead[J[f"{side}_foot"], 2] = 0.15
        behind[J[f"{side}_foot"], 2] = -0.15
    assert np.isclose(facing_score(ahead), 1.0) and np.isclose(facing_score(behind), -1.0)
    flat = ahead.copy()
    flat[:, 0] = 0.0  # every joint on the midline: no left-right extent, no facing
    assert facing_score(flat) == 0.0
