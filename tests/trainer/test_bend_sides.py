"""``pose-trainer bend-sides`` (trainer.bend_sides): the side elbows and knees bend to,
fitted on real training poses, and core.ends' tables (``serving.bend_side``) against it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from core.ends import BEND_ELBOW, BEND_KNEE, CHAINS, PREFER, mirrored_side
from core.skeleton import JOINT_NAMES
from trainer.bend_sides import agreement, fit_sides, lines_and_sides
from trainer.cli import app
from trainer.data.dataset import load_dataset


def test_the_tables_put_real_limbs_on_their_own_side(small_dataset: Path) -> None:
    poses = load_dataset(small_dataset).positions.astype(np.float64)
    for limb, shipped in (("elbow", BEND_ELBOW), ("knee", BEND_KNEE)):
        u, p = lines_and_sides(poses, limb)
        assert len(u) > 1000 and np.allclose(np.linalg.norm(p, axis=-1), 1.0)
        assert np.all(np.abs(np.sum(u * p, axis=-1)) < 1e-9)  # across the limb
        fit = fit_sides(poses, limb)
        assert fit.limbs == len(u) and fit.agree > 0.99 and fit.cosine > 0.8
        share, cosine = agreement(shipped, u, p)  # the shipped table, fitted on more poses
        assert share > 0.99 and cosine > 0.8
        # a side fixed for every limb direction does worse (the elbows most: raised arms)
        fixed = np.zeros((4, 3))
        fixed[3] = np.mean(p, axis=0)
        assert agreement(fixed, u, p)[1] < cosine


def test_right_limbs_take_the_mirror_image_of_the_left_table() -> None:
    rng = np.random.default_rng(0)
    u = rng.normal(size=(50, 3))
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    flip = np.asarray([-1.0, 1.0, 1.0])
    for left, right in ((PREFER[0], PREFER[1]), (PREFER[2], PREFER[3])):
        mirrored = ((u * flip) @ left[:3] + left[3]) * flip
        np.testing.assert_allclose(u @ right[:3] + right[3], mirrored)
    np.testing.assert_array_equal(mirrored_side(mirrored_side(BEND_KNEE)), BEND_KNEE)
    assert not PREFER[4:].any()  # the elbows' own chains: no side
    # each table on its own limb: the chain whose middle joint is the left elbow, knee
    mids = [JOINT_NAMES[int(m)] for m in CHAINS[:, 1]]
    assert np.array_equal(PREFER[mids.index("left_elbow")], BEND_ELBOW)
    assert np.array_equal(PREFER[mids.index("left_knee")], BEND_KNEE)
    assert np.array_equal(PREFER[mids.index("right_knee")], mirrored_side(BEND_KNEE))


def test_too_few_bent_limbs_is_an_error_that_says_so(small_dataset: Path) -> None:
    poses = load_dataset(small_dataset).positions[:2].astype(np.float64)
    with pytest.raises(ValueError, match="too few knees bent 90 cm or more"):
        fit_sides(poses, "knee", min_bend=0.9)


def test_the_command_prints_both_tables_beside_core_s(small_dataset: Path) -> None:
    ok = CliRunner().invoke(app, ["bend-sides", "--dataset", str(small_dataset), "--every", "2"])
    assert ok.exit_code == 0, ok.output
    lines = ok.output.splitlines()
    assert lines[0].startswith("elbow: [[") and lines[2].startswith("knee: [[")
    assert "core.ends' table: 0.99" in lines[1] or "core.ends' table: 1.0000" in lines[1]
    bad = CliRunner().invoke(app, ["bend-sides", "--dataset", str(small_dataset), "--split", "x"])
    assert bad.exit_code == 1 and "unknown split 'x'" in bad.output
    for value, says in (("1e999", "inf is not a finite number"), ("nan", "--min-bend")):
        args = ["bend-sides", "--dataset", str(small_dataset), "--min-bend", value]
        bad = CliRunner().invoke(app, args)  # (1e999, read as inf, fitted no limb: 1 before)
        words = " ".join(bad.output.replace("│", " ").split())  # (rich's box, its lines)
        assert bad.exit_code == 2 and "--min-bend" in words and says in words, bad.output
