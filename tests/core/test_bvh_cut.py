"""A file cut short (an interrupted copy): its MOTION block ends inside its last frame line,
or at the end of a line before its last declared frame. Read for some frames, both are the
same file to a user: the frames before the cut read (as the editor opens such a file), and
:attr:`core.bvh.BVH.cut` says where it ends; a frame at or past the cut, and the whole read,
are refused naming the line. An audit (2026-12-06): the first was read without a word, the
second refused whatever frame was asked."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.bvh import BVHError, Cut, parse_bvh
from tests.core.test_bvh_write import raw, relaid


def _cuts(text: str) -> dict[str, tuple[str, Cut]]:
    """The Bandai walk cut inside its last line, at the end of the line before it (its
    `Frames:` one above the lines), five lines short, and inside a line with blank lines
    after it; each with where it ends."""
    n = parse_bvh(text, "walk").num_frames
    lines = text.rstrip("\n").split("\n")
    last = len(lines)  # (1-based: the last line)
    inside = lines[-1][: lines[-1].rindex(" ", 0, len(lines[-1]) - 40)]
    kept = len(inside.split())
    return {
        "inside": ("\n".join([*lines[:-1], inside]) + "\n", Cut(n - 1, kept, last, n)),
        "line end": ("\n".join(lines[:-1]) + "\n", Cut(n - 1, 0, last - 1, n)),
        "five lines": ("\n".join(lines[:-5]), Cut(n - 5, 0, last - 5, n)),
        "blank after": ("\n".join([*lines[:-1], inside]) + "\n \n\n", Cut(n - 1, kept, last, n)),
    }


def test_a_file_cut_short_reads_its_frames_before_the_cut(bvh_files: dict[str, Path]) -> None:
    text = raw(bvh_files["bandai"])
    whole = parse_bvh(text, "walk")
    assert parse_bvh(text, "walk", frames=[1]).cut is None
    for case, (cut_text, cut) in _cuts(text).items():
        some = parse_bvh(cut_text, "walk", frames=[1, 40])
        assert some.cut == cut, case
        assert some.num_frames == whole.num_frames, case  # (as its `Frames:` declares)
        for f in (1, 40):
            assert some.row(f).tobytes() == whole.row(f).tobytes(), case
            assert some.frame_span(f) == whole.frame_span(f), case
        with pytest.raises(BVHError) as refused:  # the whole read: as before
            parse_bvh(cut_text, "walk")
        with pytest.raises(BVHError) as at_the_cut:  # a frame it does not hold whole
            parse_bvh(cut_text, "walk", frames=[1, cut.frame])
        assert str(at_the_cut.value) == str(refused.value), case
        if cut.values:
            assert f"line {cut.line}: expected 132 values per frame, got {cut.values}" in str(
                refused.value
            )
        else:
            assert f"'Frames:' declares {cut.frames} frames, found {cut.frame}" in str(
                refused.value
            )


def test_a_block_of_other_shapes_is_no_cut(bvh_files: dict[str, Path]) -> None:
    """Frames wrapped over lines or two a line, a blank line among the frames: read as
    before (a count that does not match is refused), never taken for a cut file's."""
    text = raw(bvh_files["bandai"])
    lines = text.rstrip("\n").split("\n")
    for case, bad in {
        "two frames a line": relaid(text, 264).replace("Frames:\t195", "Frames:\t196"),
        "wrapped": relaid(text, 11).replace("Frames:\t195", "Frames:\t196"),
        "blank line among": "\n".join([*lines[:-3], "", *lines[-3:-1]]),
    }.items():
        with pytest.raises(BVHError, match=r"truncated|expected"):
            parse_bvh(bad, case, frames=[1])


def test_a_file_of_one_whole_line_cut_at_its_end_is_cut_short_too() -> None:
    """A block of one line, whole, under `Frames: 5`: its frame 0 reads, the cut is after
    it (its last line was looked for before the block's start: the whole file's words
    counted as that line's, and the file refused)."""
    head = "HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\nCHANNELS 2 Xrotation Yrotation\n}\nMOTION\n"
    text = f"{head}Frames: 5\nFrame Time: 0.1\n10.000000 20.000000\n"  # (long enough for 5)
    read = parse_bvh(text, "one", frames=[0])
    assert read.cut == Cut(1, 0, 10, 5) and read.row(0).tolist() == [10.0, 20.0]


def test_a_file_cut_inside_its_hierarchy_names_where_it_ends(bvh_files: dict[str, Path]) -> None:
    """A file cut inside its HIERARCHY (no MOTION line) names its last line and says it
    looks cut short, with the '{' left open; a whole hierarchy with nothing after it, or a
    word where MOTION should be, says that instead. An audit (2026-12-06): the first 1,500
    bytes of a real file got "missing MOTION section", no line."""
    for name in ("bandai", "cmu-daz-salsa"):
        text = raw(bvh_files[name])
        head = text[:1500]
        last = head.rstrip().count("\n") + 1
        with pytest.raises(BVHError) as cut:
            parse_bvh(head, name)
        reason = cut.value.reason
        assert reason.startswith(f"line {last}: the file ends inside its HIERARCHY ("), reason
        assert "'{' not closed, no MOTION section): it looks cut short" in reason, reason
        with pytest.raises(BVHError) as some:  # (the service reads one frame: the same)
            parse_bvh(head, name, frames=[0])
        assert some.value.reason == reason
        hierarchy = text[: text.index("MOTION")]
        end = hierarchy.rstrip().count("\n") + 1  # (its last '}')
        with pytest.raises(BVHError, match=rf"line {end}: missing MOTION section: the file "
                           "ends after its HIERARCHY, which is whole"):  # fmt: skip
            parse_bvh(hierarchy, name)
        with pytest.raises(BVHError, match=rf"line {end + 1}: missing MOTION section: the "
                           "HIERARCHY is whole, and 'MOTON' follows it"):  # fmt: skip
            parse_bvh(text.replace("MOTION", "MOTON", 1), name)
    # a fault of the hierarchy before the cut is named as in a whole file
    head = raw(bvh_files["bandai"])[:1500].replace("JOINT Spine", "JOINT Hips", 1)
    with pytest.raises(BVHError, match=r"line \d+: duplicate joint name 'Hips'"):
        parse_bvh(head, "bandai")
