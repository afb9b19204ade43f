"""One limb's left and right joints crossed by a map (``left_foot = "foot.R_end"``,
``right_foot = "foot.L_end"``): the build refuses it, naming the map and the joints (real
ReActIdle clips; trainer.data.checks.crossed_limb_errors)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from core.skeleton import JOINT_INDEX, MIRROR
from trainer.cli import app
from trainer.data.build import build_dataset
from trainer.data.checks import crossed_links
from trainer.data.maps import MapError

MAPS = Path(__file__).resolve().parents[2] / "trainer" / "maps"
_REACTIDLE = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7/genuine"
#: The audit's studio map (ReActIdle's skeleton, one folder per actor).
STUDIO_MAP = """format = 2
source = "studio"
licence = "internal use only"
archive = "studio.tar.xz"
unit = "m"
up_axis = "+Y"
root_position = "add"
include = ["takes/**/*.bvh"]

[metadata]
pattern = '^takes/(?P<actor>[^/]+)/(?P<content>[a-z-]+)_(?P<take>\\d+)\\.bvh$'
name = "studio/{actor}/{content}_{take}"
content = "{content}"
actor = "{actor}"

"""


def _studio(more_mocap: Path, tmp_path: Path, swaps: dict[str, str]) -> tuple[Path, Path]:
    """Two real ReActIdle takes as a studio's (``tmp_path/mocap/studio/takes/p00N``) and
    the ReActIdle joints as its map with each ``old -> new`` of ``swaps`` applied to the
    [joints] lines; (mocap folder, map file)."""
    for n, person in enumerate(("002", "003"), start=1):
        takes = tmp_path / "mocap" / "studio" / "takes" / f"p00{n}"
        takes.mkdir(parents=True)
        shutil.copy(more_mocap / _REACTIDLE / f"{person}_genuine.bvh", takes / "idle_01.bvh")
    joints = (MAPS / "reactidle.toml").read_text().split("[joints]")[1]
    for old, new in swaps.items():
        assert old in joints
        joints = joints.replace(old, new)
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "studio.toml").write_text(STUDIO_MAP + "[joints]" + joints)
    return tmp_path / "mocap", maps / "studio.toml"


FEET = {
    'left_foot = "foot.L_end"': 'left_foot = "foot.R_end"',
    'right_foot = "foot.R_end"': 'right_foot = "foot.L_end"',
}
WRISTS = {
    'left_wrist = "forearm.L_end"': 'left_wrist = "forearm.R_end"',
    'right_wrist = "forearm.R_end"': 'right_wrist = "forearm.L_end"',
}
#: The whole left leg mapped to the right one and back: no bone is crossed, the hips are.
LEGS = {
    f'{side}_{joint} = "{bone}.{s}{end}"': f'{side}_{joint} = "{bone}.{o}{end}"'
    for side, s, o in (("left", "L", "R"), ("right", "R", "L"))
    for joint, bone, end in (
        ("hip", "thigh", ""),
        ("knee", "shin", ""),
        ("ankle", "foot", ""),
        ("foot", "foot", "_end"),
    )
}


@pytest.mark.parametrize(
    ("swaps", "said"),
    [
        (
            FEET,
            "left_foot = 'foot.R_end' and right_foot = 'foot.L_end' look crossed: the bone "
            "left_ankle -> left_foot changes its length",
        ),
        (
            WRISTS,
            "left_wrist = 'forearm.R_end' and right_wrist = 'forearm.L_end' look crossed: the "
            "bone left_elbow -> left_wrist changes its length",
        ),
        (LEGS, "the hips' and the shoulders' left-right axes point apart in 100% of the frames"),
    ],
    ids=["feet", "wrists", "whole-leg"],
)
def test_a_map_crossing_one_limbs_sides_is_refused_naming_the_map_and_joints(
    more_mocap: Path, tmp_path: Path, swaps: dict[str, str], said: str
) -> None:
    """A studio audit (2026-12-07): a map with the feet (or the wrists) crossed built and
    trained with exit 0, the build only warning of frames dropped for bone_length, and the
    models' feet 0.26 m long, not 0.155 m; the checks caught whole-body swaps alone."""
    mocap, map_file = _studio(more_mocap, tmp_path, swaps)
    out = tmp_path / "poses.npz"
    with pytest.raises(MapError) as err:
        build_dataset(mocap, out, maps_dir=map_file.parent, workers=1, progress=False)
    text = str(err.value)
    assert text.startswith(f"map {map_file}: "), text
    assert said in text, text
    assert "studio:takes/p001/idle_01.bvh (and 1 more files)" in text, text
    assert not out.exists()

    r = CliRunner().invoke(
        app, ["dataset", "--mocap", str(mocap), "--maps", str(map_file.parent), "--out", str(out)]
    )
    flat = " ".join(r.output.split())
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert f"error: map {map_file}: " in flat and said in flat, r.output


def test_the_same_takes_with_their_sides_right_build(more_mocap: Path, tmp_path: Path) -> None:
    """The check's counterpart: the map as shipped (the same two takes) builds, its feet
    their own length, and no link of its poses looks crossed."""
    mocap, map_file = _studio(more_mocap, tmp_path, {})
    out = tmp_path / "poses.npz"
    report = build_dataset(mocap, out, maps_dir=map_file.parent, workers=1, progress=False)
    assert crossed_links(report.dataset.positions) == []
    foot = report.meta["mean_bone_lengths_m"]["studio"]["left_foot"]
    assert 0.1 < foot < 0.2, foot
    assert not any(re.search("crossed|apart", w) for w in report.meta["warnings"])


def test_crossed_links_of_swapped_columns_of_real_poses(more_mocap: Path, tmp_path: Path) -> None:
    """The measure alone, on the same real poses: the two foot columns exchanged give the
    left_foot link; the whole body mirrored (every left column with its right) gives none
    (that is `swap_sides`, the toes check's)."""
    mocap, map_file = _studio(more_mocap, tmp_path, {})
    report = build_dataset(
        mocap, tmp_path / "poses.npz", maps_dir=map_file.parent, workers=1, progress=False
    )
    p = report.dataset.positions
    lf, rf = JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]
    crossed = p.copy()
    crossed[:, [lf, rf]] = p[:, [rf, lf]]
    assert [c for c, _, _ in crossed_links(crossed)] == [lf]
    assert crossed_links(p[:, np.asarray(MIRROR)]) == []
