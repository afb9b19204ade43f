"""BVH reader (core/bvh.py): hand-computed forward kinematics, any channel order, 6-channel
joints, End Sites, what a writer needs kept, clear errors, and real files of four studios."""

from __future__ import annotations

import gc
import random
import re
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.bvh import MAX_JOINTS, MAX_NAME, BVHError, parse_bvh, read_bvh
from core.bvh_words import NUMBER
from core.euler import euler_matrices
from tests.conftest import traced

# Root: 6 channels (position + Z X Y rotation), child 10 up, end site 5 up the child.
TINY = """HIERARCHY
ROOT root
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT child
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0
0 0 0 90 90 0 0 0 0
0 0 0 0 0 0 0 0 90
"""


def _refusal(text: str, frames: tuple[int, ...] | None = None) -> str:
    """The reason parse_bvh refuses ``text`` for (no exception kept: its traceback holds
    the reader's frames)."""
    try:
        parse_bvh(text, "x.bvh", frames)
    except BVHError as exc:
        return exc.reason
    raise AssertionError("read")


_MOTION = "\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n"
_TAIL = "\n{" + _MOTION
_ROOT = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\n"


def test_fk_matches_hand_computed_poses(tmp_path: Path) -> None:
    path = tmp_path / "tiny.bvh"
    path.write_text(TINY)
    bvh = read_bvh(path)
    assert bvh.joint_names == ("root", "child", "child_end")
    assert bvh.num_frames == 4
    assert bvh.num_channels == 9
    assert bvh.fps == pytest.approx(30.0, rel=1e-5)
    pos = bvh.forward_kinematics()
    expected = np.array(
        [
            # rest: root at its position channels, child 10 up, end 5 further up.
            [[1, 2, 3], [1, 12, 3], [1, 17, 3]],
            # root Rz(90) turns the child offset (0,10,0) to (-10,0,0); the child's Rx(90)
            # turns the end offset (0,5,0) to (0,0,5), and Rz(90) leaves +Z alone.
            [[1, 2, 3], [-9, 2, 3], [-9, 2, 8]],
            # intrinsic Z then X: R = Rz(90) @ Rx(90); Rx takes (0,10,0) to (0,0,10), Rz keeps
            # it. (The extrinsic reading, Rx @ Rz, would give (-10, 0, 0).)
            [[0, 0, 0], [0, 0, 10], [0, 0, 15]],
            # a child yaw does not move its own end site along its Y axis.
            [[0, 0, 0], [0, 10, 0], [0, 15, 0]],
        ],
        dtype=float,
    )
    np.testing.assert_allclose(pos, expected, atol=1e-9)
    # Subsets and frame selection give the same numbers.
    np.testing.assert_allclose(
        bvh.forward_kinematics(["child_end"], frames=slice(1, 3)), expected[1:3, 2:3], atol=1e-9
    )


def test_position_channels_replace_offsets_and_any_channel_order() -> None:
    text = """HIERARCHY
ROOT a
{
  OFFSET 100 100 100
  CHANNELS 6 Yrotation Xposition Zposition Yposition Xrotation Zrotation
  JOINT b
  {
    OFFSET 50 50 50
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 1
Frame Time: 0.01
90 1 3 2 0 0 0 10 0 0 0 0
"""
    bvh = parse_bvh(text, "order.bvh")
    assert bvh.joints[0].rotation_order == "YXZ"
    pos = bvh.forward_kinematics()
    # root at (1, 2, 3) (offset replaced), rotated Ry(90): x -> -z, z -> x.
    # b's offset replaced by (0, 10, 0) -> unchanged by Ry; end (1,0,0) -> (0,0,-1).
    np.testing.assert_allclose(pos[0], [[1, 2, 3], [1, 12, 3], [1, 12, 2]], atol=1e-9)


@pytest.mark.parametrize(
    ("mutate", "message"),
    [
        (lambda t: t.replace("MOTION", "MOTON"), "missing MOTION section"),
        (
            lambda t: t[: t.rindex("0 0 0 0 0 0 0 0 90")] + "0 0 0 0\n",
            "line 22: expected 9 values per frame, got 4",
        ),
        (lambda t: t.replace("Frames: 4", "Frames: 5"), "declares 5 frames, found 4"),
        (lambda t: t.replace("Frames: 4", "Frames: 3"), "more frame lines than the 3"),
        (
            lambda t: t.replace("1 2 3 90 0 0 0 90 0", "1 2 3 90 x 0 0 90 0"),
            "line 20: frame 1, channel root.Xrotation: not a number: 'x'",
        ),
        (lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"), "unknown channel"),
        (lambda t: t.replace("  }\n}\nMOTION", "MOTION"), "unexpected end of HIERARCHY"),
        (lambda t: "garbage\x00\x01 not a bvh at all", "not a BVH file"),
        (lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0"), "bad Frame Time"),
        # quoted as the file has it (an API audit, 2026-12-08: "bad Frame Time 0.0", "inf")
        (
            lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 1e-400"),
            "line 18: bad Frame Time '1e-400': not above 0 and finite",
        ),
        (
            lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 1" + "0" * 400),
            "line 18: bad Frame Time '1000000000",
        ),
        # each was blamed on the line before, as "bad Frames / Frame Time values"
        (
            lambda t: t.replace("Frame Time: 0.0333333", "Frame Time: 0,0333333"),
            "line 18: bad Frame Time '0,0333333': not a number",
        ),
        # a count above the names read the next keyword as a channel, and said only that
        (
            lambda t: t.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"),
            "unknown channel 'End' of joint 'child' (CHANNELS 4 lists 3?)",
        ),
    ],
)
def test_malformed_files_raise_bvherror_naming_file_and_reason(
    tmp_path: Path, mutate: Any, message: str
) -> None:
    path = tmp_path / "broken.bvh"
    path.write_text(mutate(TINY))
    with pytest.raises(BVHError) as info:
        read_bvh(path)
    assert message in str(info.value)
    assert str(path) in str(info.value)
    assert info.value.file == str(path)


def _axis(axis: str, deg: float) -> np.ndarray[Any, Any]:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return {
        "X": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
        "Y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
        "Z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
    }[axis]


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX", "ZX", "Y"])
def test_any_rotation_order_on_a_6_channel_child(order: str) -> None:
    """A child with position AND rotation channels (in any order, interleaved), its rotation
    the product of the listed axes, first listed outermost."""
    angles = {"X": 30.0, "Y": -50.0, "Z": 70.0}
    names = [f"{a}rotation" for a in order]
    chans = ["Xposition", *names[:1], "Yposition", "Zposition", *names[1:]]
    values = {"Xposition": 1.0, "Yposition": 2.0, "Zposition": 3.0}
    values.update({f"{a}rotation": angles[a] for a in order})
    text = f"""HIERARCHY
ROOT r
{{
  OFFSET 0 0 0
  CHANNELS 0
  JOINT c
  {{
    OFFSET 9 9 9
    CHANNELS {len(chans)} {" ".join(chans)}
    End Site
    {{
      OFFSET 0 0 10
    }}
  }}
}}
MOTION
Frames: 1
Frame Time: 0.01
{" ".join(str(values[c]) for c in chans)}
"""
    bvh = parse_bvh(text, "order.bvh")
    assert bvh.joints[1].channels == tuple(chans)  # kept in file order for a writer
    assert bvh.joints[1].rotation_order == order
    rot = np.eye(3)
    for a in order:
        rot = rot @ _axis(a, angles[a])
    pos = bvh.forward_kinematics(["c", "c_end"])[0]
    np.testing.assert_allclose(pos[0], [1, 2, 3], atol=1e-12)  # positions replace the offset
    np.testing.assert_allclose(pos[1], [1, 2, 3] + rot @ [0, 0, 10], atol=1e-9)
    np.testing.assert_allclose(
        euler_matrices(order, np.radians([angles[a] for a in order])), rot, atol=1e-12
    )


def test_raw_text_and_frame_lines_are_kept_for_a_writer() -> None:
    text = TINY.replace("\n", "\r\n").replace("1 2 3 90 0 0 0 90 0", "1 2 3  90.000 0 0 0 90 0")
    bvh = parse_bvh(text, "crlf.bvh")
    assert bvh.text == text
    lines = bvh.frame_lines()
    assert len(lines) == bvh.num_frames == 4
    assert lines[1] == "1 2 3  90.000 0 0 0 90 0"  # as written, spacing and all
    assert text[bvh.motion_offset :].startswith("1 2 3 0 0 0 0 0 0")
    np.testing.assert_array_equal(bvh.motion[1], [1, 2, 3, 90, 0, 0, 0, 90, 0])


def test_a_file_whose_lines_end_in_cr_alone_is_read_as_lf() -> None:
    """Classic Mac OS line ends (CR alone): read as the same file with LF ends, which is
    the text an edit is written back into (it said "missing MOTION section")."""
    lf = parse_bvh(TINY, "lf.bvh")
    cr = parse_bvh(TINY.replace("\n", "\r"), "cr.bvh")
    assert cr.text == TINY
    assert cr.motion.tobytes() == lf.motion.tobytes()
    assert [j.name for j in cr.joints] == [j.name for j in lf.joints]
    one = parse_bvh(TINY.replace("\n", "\r"), "cr.bvh", frames=[2])
    assert one.motion[2].tobytes() == lf.motion[2].tobytes()


_BODIES = [
    "1 2 3 0 0 0 0 0 0\n\n1 2 3 90 0 0 0 90 0\n \t\n0 0 0 90 90 0 0 0 0\n0 0 0 0 0 0 0 0 90",
    "1 2 3 0 0 0 0 0 0\r\n1 2 3 90 0 0 0 90 0\r\n\r\n0 0 0 90 90 0 0 0 0 0 0 0 0 0 0 0 0 90\r\n",
    "1 2 3 0 0 0 0 0 0 1 2 3 90 0 0 0 90 0 0 0 0 90 90 0 0 0 0 0 0 0 0 0 0 0 0 90\n",
    " \n1 2 3 0 0 0 0 0 0\n\n\n1 2 3 90 0 0 0 90 0\n0 0 0 90 90 0 0 0 0\n0 0 0 0 0 0 0 0 90\n\t ",
]  # one frame a line, but blank lines; frames across lines


@pytest.mark.parametrize("body", _BODIES)
def test_frame_line_count_is_the_number_of_frame_lines(body: str) -> None:
    bvh = parse_bvh(TINY.split("1 2 3 0")[0] + body, "lines.bvh")
    assert bvh.num_frames == 4
    assert bvh.frame_line_count() == len(bvh.frame_lines())
    assert bvh.frame_line_count() == len([ln for ln in body.splitlines() if ln.strip()])


_NOT_BVH_NUMBERS = ["1_000", "١", "٣.5", "１", "nan", "-NaN", "inf", "+Infinity", "0x1p3", "1,5"]


@pytest.mark.parametrize("word", _NOT_BVH_NUMBERS)
def test_only_ascii_decimals_are_numbers(word: str) -> None:
    """Python's ``float()`` reads ``1_000``, other scripts' digits and ``nan``/``inf``,
    numpy's reader ``nan`` and ``inf``: no BVH writer writes them (an audit found the first
    two read, 2026-12-06). Each is refused with its line: a value of the frames read whole
    or one alone, an OFFSET, the Frame Time."""
    hint = "(BVH numbers are finite decimals: -1.5, 2e-3)"
    frame = TINY.replace("1 2 3 90 0 0 0 90 0", f"1 2 3 {word} 0 0 0 90 0")
    at = "line 20: frame 1, channel root.Zrotation"
    assert _refusal(frame) == f"{at}: not a number: {word!r} {hint}"
    assert _refusal(frame, (1,)) == f"{at}: not a number: {word!r} {hint}"
    assert parse_bvh(frame, "x", (2,)).row(2).tolist() == [0, 0, 0, 90, 90, 0, 0, 0, 0]
    offset = TINY.replace("OFFSET 0 10 0", f"OFFSET 0 {word} 0")
    assert _refusal(offset) == f"line 8: 'OFFSET of child': not a number: {word!r} {hint}"
    frame_time = TINY.replace("Frame Time: 0.0333333", f"Frame Time: {word}")
    assert _refusal(frame_time) == f"line 18: bad Frame Time {word!r}: not a number"


def test_a_number_is_what_the_number_pattern_reads() -> None:
    """``core.bvh_words.as_number`` (``float()``, then a check cheaper than the pattern)
    takes the words ``NUMBER_RE`` takes, with ``float()``'s value, and no other."""
    import random
    import struct

    from core.bvh_words import NUMBER_RE, as_number

    rng = random.Random(0)
    alphabet = "0123456789+-.eE_naifty NAIFTYx١٣１²"
    for _ in range(200_000):
        word = "".join(rng.choice(alphabet) for _ in range(rng.randint(1, 9))).strip() or "0"
        want = float(word) if NUMBER_RE.fullmatch(word) else None
        got = as_number(word)
        assert (got is None) == (want is None), word
        assert want is None or struct.pack("d", got) == struct.pack("d", want), word


@pytest.mark.parametrize("word", ["1_0", "٣", "３", "3.0", "1e1", "x"])
def test_counts_are_ascii_whole_numbers(word: str) -> None:
    """A channel count and the frame count are ASCII digits (``int()`` also reads ``1_0``
    and ``٣``)."""
    channels = TINY.replace("CHANNELS 3 Zrotation", f"CHANNELS {word} Zrotation")
    assert _refusal(channels) == f"line 9: bad channel count {word!r}: not a whole number >= 0"
    assert _refusal(TINY.replace("Frames: 4", f"Frames: {word}")) == (
        f"line 17: bad frame count {word!r}"
    )


def test_a_frame_count_of_thousands_of_digits_is_not_quoted_whole() -> None:
    """An API audit (2026-12-08): a 3,000-digit ``Frames:`` count over 4 frame lines was
    quoted whole, a 3,061-character detail; details quote client input clipped."""
    count = "9" * 3000
    said = _refusal(TINY.replace("Frames: 4", f"Frames: {count}"))
    assert said == (
        "line 22: truncated: 'Frames:' declares <an integer of 3000 digits> frames, found 4"
    )


def test_decimals_as_writers_write_them_are_read_as_float_reads_them() -> None:
    """Signs, a point at either end, exponents, leading zeros: the values ``float()``
    gives, read whole or one frame alone, and in an OFFSET. A decimal past the float range
    is infinite (the service refuses it, naming its channel: tests/service)."""
    words = ["+1.5", "-.5", "5.", "1E3", "-0", "1e-300", "007", "2.5e+2", "-1.25E-2"]
    text = TINY.replace("1 2 3 90 0 0 0 90 0", " ".join(words))
    want = np.array([float(w) for w in words])
    assert parse_bvh(text, "ok").row(1).tobytes() == want.tobytes()
    assert parse_bvh(text, "ok", (1,)).row(1).tobytes() == want.tobytes()
    offset = parse_bvh(TINY.replace("OFFSET 0 10 0", "OFFSET +.5 -0 1E1"), "ok").joints[1]
    assert offset.offset == (0.5, -0.0, 10.0)
    huge = parse_bvh(TINY.replace("1 2 3 90 0 0 0 90 0", "1 2 3 1e999 0 0 0 90 0"), "ok")
    assert huge.row(1)[3] == np.inf


def test_a_blank_frame_line_holds_no_value() -> None:
    """numpy's reader reads -1 of whitespace alone: a file of one channel whose one frame
    line was blank read as -1 (a fuzz of the number forms found it)."""
    text = _ROOT.replace("\n}\n", "\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n \n", 1)
    assert _refusal(text) == "line 9: truncated: 'Frames:' declares 1 frames, found 0"
    assert _refusal(text, (0,)) == "line 9: truncated: 'Frames:' declares 1 frames, found 0"
    assert parse_bvh(text.replace(" \n", "-1\n"), "ok").row(0).tolist() == [-1.0]


def test_a_joint_keeps_its_name_where_an_end_site_would_take_it() -> None:
    """Found by a users' files audit (2026-12-05): a joint called ``X_end`` beside X's End
    Site was refused ('duplicate joint name', or 'End Site name ... is taken'), though the
    file names nothing twice: the End Site's name is the reader's own."""
    # the root's End Site after a joint named "root_end"
    after = TINY.replace("JOINT child", "JOINT root_end").replace(
        "  }\n}\nMOTION", "  }\n  End Site\n  {\n    OFFSET 1 0 0\n  }\n}\nMOTION"
    )
    bvh = parse_bvh(after, "after.bvh")
    assert bvh.joint_names == ("root", "root_end", "root_end_end", "root_end2")
    assert [j.end_site for j in bvh.joints] == [False, False, True, True]
    assert bvh.joints[3].parent == 0 and bvh.joints[3].offset == (1.0, 0.0, 0.0)
    # the child's End Site before a joint named "child_end" (its sibling's child)
    before = TINY.replace(
        "      OFFSET 0 5 0\n    }\n",
        "      OFFSET 0 5 0\n    }\n    JOINT child_end\n    {\n      OFFSET 0 1 0\n"
        "      CHANNELS 3 Zrotation Xrotation Yrotation\n      End Site\n      {\n"
        "        OFFSET 0 2 0\n      }\n    }\n",
    ).replace("0 0 0 0 0 0 0 0 90\n", "0 0 0 0 0 0 0 0 90 0 0 0\n")
    before = (
        "\n".join(
            line + " 0 0 0" if line[:1].isdigit() and line.count(" ") == 8 else line
            for line in before.splitlines()
        )
        + "\n"
    )
    bvh = parse_bvh(before, "before.bvh")
    assert bvh.joint_names == ("root", "child", "child_end2", "child_end", "child_end_end")
    assert bvh.motion.shape == (4, 12)
    # unclashed names are as they always were
    renamed = parse_bvh(TINY.replace("JOINT child", "JOINT child_end"), "ok.bvh")
    assert renamed.joint_names == ("root", "child_end", "child_end_end")


def test_a_hierarchy_of_more_joints_than_a_character_has_is_refused_where_it_passes() -> None:
    """An 8 MiB body of End Sites held ~295,000 joints, and reading them took seconds (an
    API audit, 2026-12-05): the reader stops at the first joint past ``MAX_JOINTS``."""

    def with_ends(n: int) -> str:
        ends = "    End Site\n    {\n      OFFSET 0 5 0\n    }\n" * n
        return TINY.replace("    End Site\n    {\n      OFFSET 0 5 0\n    }\n", ends)

    assert len(parse_bvh(with_ends(MAX_JOINTS - 2), "most.bvh").joints) == MAX_JOINTS
    first_past = 10 + 4 * (MAX_JOINTS - 2)  # the line of the End Site past the limit
    with pytest.raises(BVHError, match=f"line {first_past}: more than {MAX_JOINTS} joints"):
        parse_bvh(with_ends(MAX_JOINTS - 1), "past.bvh")
    with pytest.raises(BVHError, match=f"line {first_past}: more than {MAX_JOINTS} joints"):
        parse_bvh(with_ends(200_000), "flood.bvh")  # said where it passed, not at the end
    # and channels: one joint of 400,000 rotation channels was the audit's other file
    many = "CHANNELS 12 " + "Zrotation Xrotation Yrotation " * 4
    motion = "\n".join(" ".join(["0"] * 18) for _ in range(4))
    ok = TINY.replace("CHANNELS 3 Zrotation Xrotation Yrotation", many.strip())
    ok = ok.split("Frame Time: 0.0333333\n")[0] + "Frame Time: 0.0333333\n" + motion + "\n"
    assert parse_bvh(ok, "twelve.bvh").joints[1].rotation_order == "ZXY" * 4
    flood = TINY.replace("CHANNELS 3 Zrotation", "CHANNELS 400000 Zrotation")
    with pytest.raises(BVHError, match="line 9: 400000 channels on joint 'child': at most 12"):
        parse_bvh(flood, "flood.bvh")


def test_reactidle_file_with_6_channel_joints(more_mocap: Path) -> None:
    """ReActIdle: most joints carry 6 channels (positions within 2 cm of the offsets), one
    joint ``YXZ``; metres; 24 fps; the root's positions are a displacement from its OFFSET."""
    from tests.conftest import _RI

    bvh = read_bvh(more_mocap / f"{_RI}/genuine/003_genuine.bvh")
    assert bvh.fps == pytest.approx(24.0, rel=1e-4)
    six = [j.name for j in bvh.joints if len(j.channels) == 6]
    assert len(six) >= 15 and "thigh.L" in six and "forearm.R" in six
    assert bvh.joints[bvh.index("shoulder.L")].rotation_order == "YXZ"
    assert {"forearm.L_end", "foot.R_end", "face_end"} <= set(bvh.joint_names)
    j = bvh.joints[bvh.index("shin.L")]
    cols = [j.channel_start + k for k, c in enumerate(j.channels) if c.endswith("position")]
    np.testing.assert_allclose(
        bvh.motion[:, cols], np.broadcast_to(j.offset, (bvh.num_frames, 3)), atol=0.02
    )
    pos = bvh.forward_kinematics(["pelvis", "shin.L", "foot.L"])
    thigh = np.linalg.norm(pos[:, 1] - pos[:, 0], axis=-1)
    assert 0.3 < np.median(thigh) < 0.45  # metres
    # Root positions replace the OFFSET: the pelvis is near y = 0, about an OFFSET too low.
    assert abs(pos[:, 0, 1].mean()) < 0.05 < bvh.joints[0].offset[1]


def test_fair_child_file_in_inches_z_up(more_mocap: Path) -> None:
    from tests.conftest import _FAIR

    bvh = read_bvh(more_mocap / f"{_FAIR}/fair1/dab.bvh")
    assert bvh.fps == pytest.approx(30.0, rel=1e-4)
    pos = bvh.forward_kinematics(["Hips", "Head", "LeftToeBase", "LeftArm", "RightArm"])
    # +Z up: the head is above the toes along Z, not Y; inches (a child's ~1 m in metres).
    height_in = np.median(pos[:, 1, 2] - pos[:, 2, 2])
    assert 30 < height_in < 45
    assert np.median(np.abs(pos[:, 1, 1] - pos[:, 2, 1])) < 10


_PLAIN = "1 2 3 0 0 0 0 0 0\n1 2 3 90 0 0 0 90 0\n0 0 0 90 90 0 0 0 0\n0 0 0 0 0 0 0 0 90"


@pytest.mark.parametrize(
    "body",
    [_PLAIN + "\n", _PLAIN, _PLAIN.replace("\n", " \t\r\n") + "\r\n", _PLAIN + "\n  ", *_BODIES],
)
def test_reading_some_frames_reads_them_as_the_whole_read_does(body: str) -> None:
    """``frames=``: those rows bit for bit as a whole read gives them, the others NaN and
    refused by ``row``, the lines' spans the writer's; out-of-range frames are not read. A
    block with blank lines among its frames, or frames across lines (``_BODIES``), is
    read so too, each frame's span its values' words (it was read whole, and written
    whole: an audit, 2026-12-06)."""
    text = TINY.split("1 2 3 0")[0] + body
    whole = parse_bvh(text, "lines.bvh")
    some = parse_bvh(text, "lines.bvh", frames=[1, 3, 7])
    assert whole.read is None
    assert some.read == {1, 3}
    for f in (1, 3):
        assert some.row(f).tobytes() == whole.row(f).tobytes()
        assert some.spans[f] == whole.frame_span(f)  # the writer's, found by the reader
    assert np.isnan(some.motion[[0, 2]]).all()
    with pytest.raises(ValueError, match="frame 0 was not read"):
        some.row(0)
    with pytest.raises(ValueError, match="only frames"):  # no NaN written or posed
        some.forward_kinematics()
    # a bad value in the frame read is found as the whole read finds it, in another not
    bad = text.replace("0 0 0 90 90 0 0 0 0", "0 0 0 90 nope 0 0 0 0")
    line = bad[: bad.index("nope")].count("\n") + 1
    with pytest.raises(
        BVHError, match=rf"line {line}: frame 2, channel root\.Xrotation: not a number: 'nope'"
    ) as whole_error:
        parse_bvh(bad, "bad.bvh")
    with pytest.raises(BVHError) as some_error:
        parse_bvh(bad, "bad.bvh", frames=[2])
    assert str(some_error.value) == str(whole_error.value)
    assert parse_bvh(bad, "bad.bvh", frames=[1]).row(1).tobytes() == whole.row(1).tobytes()


_NAN = "(BVH numbers are finite decimals: -1.5, 2e-3)"


def _first_fault(body: str, first: int, n_frames: int, n_channels: int, some: bool) -> str | None:
    """What the MOTION reader says of ``body``, as it said it when it split the block and
    its lines whole (the reference the bounded reader is held to); ``some``: reading some
    frames, line by line where the block holds one frame a line and no blank line."""
    lines = body.split("\n")
    ends = lines[:-1] if not lines[-1].strip() else lines  # (a blank last line is no frame)
    read = 2 * n_frames * n_channels <= len(body) + 1  # (else read whole: too short)
    if some and read and len(ends) == n_frames and all(map(str.strip, ends)):
        for k, line in enumerate(ends):
            if len(line.split()) != n_channels:
                return f"line {first + k}: expected {n_channels} values per frame, got " + str(
                    len(line.split())
                )
            bad = [i for i, w in enumerate(line.split()) if not re.fullmatch(NUMBER, w)]
            if bad:
                at = f"frame {k}, channel r.{'XY'[bad[0]]}rotation"
                return f"line {first + k}: {at}: not a number: {line.split()[bad[0]]!r} {_NAN}"
        return None
    if len(body.split()) != n_frames * n_channels:
        seen, last = 0, -1
        for k, line in enumerate(lines):
            count = len(line.split())
            if count and seen >= n_frames:
                return f"line {first + k}: more frame lines than the {n_frames} declared in " + (
                    "'Frames:'"
                )
            if count and count != n_channels:
                return f"line {first + k}: expected {n_channels} values per frame, got {count}"
            seen, last = (seen + 1, k) if count else (seen, last)
        ends = f"line {first + last}: truncated"
        return f"{ends}: 'Frames:' declares {n_frames} frames, found {seen}"
    words = 0  # before the line
    for k, line in enumerate(lines):
        bad = [i for i, w in enumerate(line.split()) if not re.fullmatch(NUMBER, w)]
        if bad:
            frame, column = divmod(words + bad[0], n_channels)
            at = f"frame {frame}, channel r.{'XY'[column]}rotation"
            return f"line {first + k}: {at}: not a number: {line.split()[bad[0]]!r} {_NAN}"
        words += len(line.split())
    return None


@pytest.mark.parametrize("window", [1, 4, 1 << 14])
def test_motion_faults_are_found_as_when_the_block_was_split_whole(
    window: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The MOTION block's words are counted a window at a time, its lines found one by one
    and its numbers checked by one regex (no list of every word or line: an 8 MB block's
    took 128-273 MiB): what the reader says of a random block is what it said when it split
    it whole, read whole or frame by frame, whatever the window."""
    from core import bvh_words

    monkeypatch.setattr(bvh_words, "WINDOW", window)
    rng = random.Random(window)
    words = ["0", "1.5", "-2e3", ".5", "1e999", "x", "nan", "1_0", "١", "+7."]
    head = _ROOT.replace("CHANNELS 1 Xrotation", "CHANNELS 2 Xrotation Yrotation")
    for _ in range(3000):
        n_frames = rng.randint(0, 3)
        body = "".join(
            rng.choice([*words[:5] * 4, *words[5:]]) + rng.choice([" ", " ", "\n", "\t", "\r\n"])
            for _ in range(rng.randint(0, 8))
        )
        text = f"{head}MOTION\nFrames: {n_frames}\nFrame Time: 0.1\n{body}"
        for frames in (None, tuple(range(n_frames))):
            want = _first_fault(body, 10, n_frames, 2, frames is not None)
            try:
                read = parse_bvh(text, "x", frames)
            except BVHError as exc:
                got: str | None = exc.reason
            else:
                got = None
                values = [float(w) for w in body.split()]
                assert read.motion.ravel().tolist() == values, (repr(body), frames)
            assert got == want, (repr(body), frames)


_H2 = _ROOT + "MOTION\n"  # one channel


@pytest.mark.parametrize(
    ("text", "frames", "reason"),
    [  # (8.4 MB each; the old reader's peaks: 128, 273, 257, 254 MiB; the nan block was read)
        (_H2 + "Frames: 1\nFrame Time: 0.1\n" + "0.0 " * 2_100_000, (0,), "line 10: expected 1 "),
        (_H2 + "Frames: 1\nFrame Time: 0.1\n\n" + "0.0 " * 2_100_000, None, "line 11: expected 1"),
        (_H2 + "Frames: 1\nFrame Time: 0.1\n\n" + "0.0 " * 2_100_000 + "x", None, "line 11: exp"),
        (_H2 + "Frames: 2\nFrame Time: 0.1\n" + "0.0\n" * 2_100_000, None, "line 12: more frame"),
        (
            _H2 + "Frames: 2100000\nFrame Time: 0.1\n" + "nan\n" * 2_100_000,
            None,
            "line 10: frame 0, ",
        ),
    ],
    ids=["a-frame-line", "whole", "whole-and-a-word", "lines", "nan-lines"],
)
def test_a_huge_motion_block_is_refused_in_bounded_memory(
    text: str, frames: tuple[int, ...] | None, reason: str
) -> None:
    """A MOTION block's faults are found without a list of its words or lines: an 8 MB
    block of 2 M values takes numpy's table of them (16 MiB) and a copy of the block at
    most, where splitting it took 128-273 MiB."""
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        got = _refusal(text, frames)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert got.startswith(reason), got
    assert peak < 48 << 20, peak


def test_no_frames_and_a_word_that_is_no_number_are_no_empty_motion() -> None:
    """numpy's reader failing on a word left an empty table, which 'Frames: 0' took for all
    the values: the block's words were never looked at (the fuzz against the old reader's
    words found it)."""
    text = _H2 + "Frames: 0\nFrame Time: 0.1\nx\n"
    assert _refusal(text) == "line 10: more frame lines than the 0 declared in 'Frames:'"
    assert parse_bvh(_H2 + "Frames: 0\nFrame Time: 0.1\n\n", "ok").motion.shape == (0, 1)


def test_a_block_too_short_for_its_values_is_refused_without_a_table_for_them() -> None:
    """A review's find: the reader made the NaN table of every frame and channel before
    looking at a line, so a 0.2 MB body declaring 1,000 channels and 100,000 one-value lines
    filled 0.8 GB (a 4 MB one asked for 1.46 TiB: a 500). Now it is read whole, which
    compares the count of values first. (Its 1,000 channels were one joint's; a joint may
    list 12 now, so they are spread over a chain.)"""
    # 84 joints of 12 channels in a chain (the most one joint may list): 1,008 values a frame
    joint = "JOINT j\n{\n OFFSET 0 1 0\n CHANNELS 12 " + "Xrotation " * 12 + "\n"
    head = "HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 12 " + "Xrotation " * 12 + "\n"
    head += "".join(joint.replace("j", f"j{k}", 1) for k in range(83))
    text = head + " End Site\n {\n OFFSET 0 1 0\n }\n" + "}\n" * 84 + "MOTION\nFrames: 100000\n"
    text += "Frame Time: 0.01\n"
    first = text.count("\n") + 1  # the line of the first frame
    text += "0\n" * 100_000
    tracemalloc.start()
    try:
        with pytest.raises(BVHError, match=f"line {first}: expected 1008 values per frame, got 1"):
            parse_bvh(text, "x", [0])
        assert tracemalloc.get_traced_memory()[1] < 50e6
    finally:
        tracemalloc.stop()


def test_reading_one_frame_of_real_files_is_bit_identical(more_mocap: Path) -> None:
    """Every frame of a real file (a fifth of them, and the last), read alone, is the row
    the whole read gives."""
    for path in sorted(more_mocap.rglob("*.bvh"))[:3]:
        text = path.read_text()
        whole = parse_bvh(text, path.name)
        picks = [*range(0, whole.num_frames, 5), whole.num_frames - 1]
        some = parse_bvh(text, path.name, frames=picks)
        assert some.read == set(picks), path
        assert some.motion[picks].tobytes() == whole.motion[picks].tobytes(), path
        assert all(some.spans[f] == whole.frame_span(f) for f in picks[::20]), path


@pytest.mark.parametrize("window", [1, 2, 5, 1 << 14])
def test_hierarchy_words_and_lines_are_those_of_its_lines_split(
    window: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The hierarchy's words, split a window at a time (``core.bvh_words.Tokens``), and their
    lines are ``str.split()``'s of each line where lines end at \\n, \\r\\n or \\r only
    (as ``re.split(r"\\r\\n|\\r|\\n")``: not at U+0085 or U+2028, which a Latin-1 joint
    name may hold), less a byte order mark opening the file; whatever the window."""
    import random
    import re

    from core import bvh_words
    from core.bvh_words import Tokens

    monkeypatch.setattr(bvh_words, "WINDOW", window)
    ends = re.compile(r"\r\n|\r|\n")
    rng = random.Random(window)
    for _ in range(3000):
        text = "".join(
            rng.choice("ab \t\r\n\x85\u2028\x1c\ufeff") for _ in range(rng.randint(0, 40))
        )
        lines = ends.split(text)
        lines[0] = lines[0].removeprefix("\ufeff")
        want = [(k, w) for k, line in enumerate(lines, start=1) for w in line.split()]
        toks = Tokens("t", text, len(text))
        got = []
        while toks.peek() is not None:
            got.append((toks.line(), toks.next("a word")))
        assert got == want, repr(text)
        assert toks.line() == (want[-1][0] if want else 1), repr(text)
    # words up to MAX_NAME characters long, wherever a window is cut
    words, spaces = ["a", "b", "x" * (MAX_NAME - 2), "y" * MAX_NAME], [" ", "\r", "\r\n", "\n\t"]
    for _ in range(300):
        text = "".join(rng.choice(words) + rng.choice(spaces) for _ in range(rng.randint(1, 9)))
        lines = ends.split(text)
        want = [(k, w) for k, line in enumerate(lines, start=1) for w in line.split()]
        toks = Tokens("t", text, len(text))
        assert [(toks.line(), toks.next("a word")) for _ in want] == want, repr(text)
    # a word of MAX_NAME characters where a window is cut, then \r\n: one line break
    for before in ("x ", "x\n", "xy\r\n", "x  "):
        text = before + "a" * MAX_NAME + "\r\nb\rc"
        toks = Tokens("t", text, len(text))
        got = [(toks.line(), toks.next("a word")) for _ in range(4)]
        first = 1 + ("\n" in before)
        assert got == [
            (1, before.strip()),
            (first, "a" * MAX_NAME),
            (first + 1, "b"),
            (first + 2, "c"),
        ]


@pytest.mark.parametrize(
    ("text", "reason"),
    [  # (8.3 MB each, as much as a request body holds)
        ("HIERARCHY\nROOT " + "a " * 4_150_000 + _TAIL, "line 2: a joint name of more than 200"),
        ("HIERARCHY\n" + "a\n" * 4_150_000 + _MOTION, "line 2: no ROOT joint in HIERARCHY"),
        (_ROOT + "a " * 4_150_000 + _MOTION, "line 7: unexpected 'a' after the hierarchy"),
        ("HIERARCHY\nROOT " + "a" * 8_300_000 + _TAIL, "line 2: a word of more than 200"),
        ("HIERARCHY\nROOT r\n{\nOFFSET 1 " + "1" * 8_300_000 + _TAIL, "line 4: a word of more"),
    ],
    ids=["one-line-of-words", "lines-of-a-word", "after-the-root", "a-long-name", "a-long-number"],
)
def test_a_huge_hierarchy_is_refused_at_its_first_fault_and_nothing_is_kept(
    text: str, reason: str
) -> None:
    """An audit (2026-12-06) sent 8 MB hierarchies of 4 M words: the reader split them all
    before looking at one (2.2-3.9 s, +430 MiB), and its recursive nested function, a
    reference cycle, kept them after the refusal until a full collection (five requests took
    a worker from 0.3 to 2.4 GiB). Now each is refused at its first fault or limit, its line
    named, in bounded memory, and nothing of it is left without the cyclic collector."""
    got, took, held, peak = traced(lambda: _refusal(text))
    assert got.startswith(reason), got
    assert len(got) < 400
    assert peak < 4 << 20, peak  # (was 430-450 MiB)
    assert held < 1 << 20, held  # (was 380-405 MiB; a tuple free list holds ~0.1 MiB)
    assert took < 2.0, took  # (~0.1 s traced; was 5-17 s traced)


def test_names_and_words_past_max_name_are_refused_where_they_stand() -> None:
    """A joint name is at most MAX_NAME characters, its words joined by one space (the
    skeleton form's limit), and no word of the hierarchy is longer."""
    name = " ".join(["w" * 9] * 20)  # 199 characters
    ok = TINY.replace("JOINT child", f"JOINT {name}x")
    assert parse_bvh(ok, "ok.bvh").joints[1].name == f"{name}x"
    assert _refusal(TINY.replace("JOINT child", f"JOINT {name}xy")).startswith(
        f"line 6: a joint name of more than {MAX_NAME} characters: 'wwwwwwwww "
    )
    assert _refusal(TINY.replace("JOINT child", f"JOINT {name} x")).startswith(
        f"line 6: a joint name of more than {MAX_NAME}"
    )
    word = "9" * (MAX_NAME + 1)
    assert _refusal(TINY.replace("OFFSET 0 10 0", f"OFFSET 0 {word} 0")) == (
        f"line 8: a word of more than {MAX_NAME} characters: '{'9' * 99}…' (no joint name, "
        "keyword or number is so long)"
    )
    assert parse_bvh(TINY.replace("OFFSET 0 10 0", f"OFFSET 0 {word[1:]} 0"), "ok").joints


def test_reading_and_writing_leave_no_reference_cycle() -> None:
    """Neither the reader nor the writer leaves cyclic garbage (the reader's recursive
    nested function was one, the writer's too), read or refused: what they made is freed
    as soon as it is dropped, without the cyclic collector."""
    from core.bvh_write import format_bvh

    bvh_text = TINY
    gc.collect()
    gc.disable()
    try:
        for _ in range(3):
            format_bvh(parse_bvh(bvh_text, "ok.bvh"))
            parse_bvh(bvh_text, "ok.bvh", frames=(1,))
            _refusal(bvh_text.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"))
            _refusal(bvh_text.replace("    End Site", "    JOINT c2\n    End Site"))
        assert gc.collect() == 0
    finally:
        gc.enable()
