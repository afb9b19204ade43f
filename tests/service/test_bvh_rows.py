"""A malformed row in a frame the service does not read is told of (``rows_warning``).

The service parses only the frames it edits or inspects; an audit (2026-12-07) sent the
FAIR child's file with frame 5's row one value short (83 of 84), one long, and a ``nan``
on frame 7, edited frame 0, and got 200 with ``cut_short: null`` and no word. Now solve,
batch and inspect name the first such row's line and frame; the answer is as before.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

import core.bvh_rows
from core.bvh import parse_bvh
from core.bvh_rows import odd_row
from tests.core.test_bvh_write import raw


def _variants(text: str) -> dict[str, tuple[str, int, str]]:
    """The Bandai walk spoilt one row at a time: name -> (text, the row's frame, what
    the warning says it holds). (Its last row short is a file cut short: ``cut_short``.)"""
    lines = text.split("\n")
    first = lines.index("MOTION") + 3
    n = len(lines[first].split())
    out = {}
    for name, frame, spoil, said in [
        ("short", 5, lambda w: w[:-1], f"{n - 1} values"),
        ("long", 5, lambda w: [*w, "1.0"], f"{n + 1} values"),
        ("nan", 7, lambda w: [*w[:10], "nan", *w[11:]], "'nan', not a number"),
        ("comma", 150, lambda w: [*w[:3], "1,5", *w[4:]], "'1,5', not a number"),
        ("next to last", 193, lambda w: w[:-2], f"{n - 2} values"),
    ]:
        spoilt = list(lines)
        spoilt[first + frame] = " ".join(spoil(lines[first + frame].split()))
        out[name] = ("\n".join(spoilt), frame, said)
    return out


def test_a_bad_row_elsewhere_is_named_and_the_answer_kept(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    text = raw(bvh_files["bandai"])
    first = text.split("\n").index("MOTION") + 4  # frame 0's line, 1-based
    body = {"frame": 0, "targets": [{"joint": "Hand_L", "position": [30.0, 100.0, 20.0]}]}
    clean = client.post("/v1/bvh/solve", json={**body, "bvh": text}).json()
    assert clean["rows_warning"] is None
    for name, (spoilt, frame, said) in _variants(text).items():
        r = client.post("/v1/bvh/solve", json={**body, "bvh": spoilt})
        assert r.status_code == 200, r.text
        out = r.json()
        warning = out["rows_warning"]
        assert warning.startswith(f"bvh: line {first + frame}: frame {frame} holds {said}"), name
        assert out["cut_short"] is None
        assert out["changed_joints"] == clean["changed_joints"], name
        row = clean["bvh"].split("\n")[first - 1]
        assert out["bvh"].split("\n")[first - 1] == row, name  # the edit as before
        assert out["bvh"].split("\n")[first + frame - 1] == spoilt.split("\n")[first + frame - 1]
        batch = client.post(
            "/v1/bvh/solve/batch", json={"bvh": spoilt, "edits": [body]}
        ).json()  # fmt: skip
        seen = client.post("/v1/bvh/inspect", json={"bvh": spoilt, "frame": 0}).json()
        assert batch["rows_warning"] == seen["rows_warning"] == warning, name
    # the row edited is read, and refused, as before
    spoilt, frame, _ = _variants(text)["short"]
    r = client.post("/v1/bvh/solve", json={**body, "bvh": spoilt, "frame": frame})
    assert r.status_code == 422 and f"line {first + frame}" in r.json()["detail"], r.text


def test_a_file_cut_short_is_told_by_cut_short_alone(
    client: Any, bvh_files: dict[str, Path]
) -> None:
    from tests.core.test_bvh_cut import _cuts

    text = raw(bvh_files["bandai"])
    for case, (cut_text, _) in _cuts(text).items():
        seen = client.post("/v1/bvh/inspect", json={"bvh": cut_text, "frame": 40}).json()
        assert seen["cut_short"] is not None and seen["rows_warning"] is None, case


@pytest.mark.parametrize("chunk", [64, 1000, 1 << 20])
def test_odd_row_counts_as_str_split_does(
    bvh_files: dict[str, Path], chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every spoilt row found where ``str.split`` finds it, whatever the chunks (a row
    across two, a chunk within a row), spaces past ASCII too (U+3000 splits a value)."""
    monkeypatch.setattr(core.bvh_rows, "_CHUNK", chunk)
    text = raw(bvh_files["bandai"])
    cases = _variants(text)
    cases["wide"] = (text.replace(" ", "\u3000", 1), -1, "")
    lines = text.split("\n")
    first = lines.index("MOTION") + 3
    spoilt = list(lines)
    spoilt[first + 60] = spoilt[first + 60].replace(".", "\u3000", 1)  # a value split
    cases["wide row"] = ("\n".join(spoilt), 60, f"{len(lines[first].split()) + 1} values")
    for name, (t, frame, said) in cases.items():
        bvh = parse_bvh(t, frames=[0])
        got = odd_row(bvh.text, bvh.motion_offset, first + 1, bvh.num_frames, bvh.num_channels)
        if frame < 0:
            assert got is None, name
            continue
        assert got is not None and got.frame == frame and got.line == first + 1 + frame, name
        assert got.detail.startswith(said), (name, got)


def test_odd_row_parses_no_number_of_a_writers_file(
    bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The look is no parse: over CMU salsa's 2.9 MB (``-9.35e-15`` and all) no chunk has
    its numbers read, no word is read as a number (~4 ms a MB measured; the whole read of
    the file takes 74: speed is ``make bench``'s, this is what keeps it)."""
    text = raw(bvh_files["cmu-daz-salsa"])
    bvh = parse_bvh(text, frames=[0])
    read = _counted(monkeypatch, "_first_beyond", "_beyond")
    assert odd_row(bvh.text, bvh.motion_offset, 1, bvh.num_frames, bvh.num_channels, 1e7) is None
    assert read == {"_first_beyond": 0, "_beyond": 0}


def _counted(monkeypatch: pytest.MonkeyPatch, *names: str) -> dict[str, int]:
    """Calls of ``core.bvh_rows``'s functions ``names``, counted as they are made."""
    calls = dict.fromkeys(names, 0)
    for name in names:
        real = getattr(core.bvh_rows, name)

        def counting(*args: Any, _name: str = name, _real: Any = real) -> Any:
            calls[_name] += 1
            return _real(*args)

        monkeypatch.setattr(core.bvh_rows, name, counting)
    return calls


def _spoilt_word(text: str, frame: int, column: int, word: str) -> str:
    """``text`` (one frame a line) with frame ``frame``'s value ``column`` written ``word``."""
    lines = text.split("\n")
    at = lines.index("MOTION") + 3 + frame
    values = lines[at].split()
    values[column] = word
    lines[at] = " ".join(values)
    return "\n".join(lines)


@pytest.mark.parametrize(
    ("word", "said"),
    [
        ("1e400", "'1e400', out of range (no finite number)"),
        ("-1E+400", "'-1E+400', out of range (no finite number)"),
        ("2.5e7", "'2.5e7', beyond ±1e+07"),
        ("-123456789.5", "'-123456789.5', beyond ±1e+07"),
    ],
)
def test_a_number_out_of_range_elsewhere_is_named(
    client: Any, bvh_files: dict[str, Path], word: str, said: str
) -> None:
    """An API audit (2026-12-07): a value past any float (``1e400``) or past the ±1e7 a
    frame read is refused beyond, in a frame not read, was answered without a word; an edit
    of that frame is a 422. Values within it (``1e7``, ``-9.35e-15``) are no warning."""
    text = raw(bvh_files["bandai"])
    first = text.split("\n").index("MOTION") + 4  # frame 0's line, 1-based
    body = {"frame": 0, "targets": [{"joint": "Hand_L", "position": [30.0, 100.0, 20.0]}]}
    spoilt = _spoilt_word(text, 9, 20, word)
    out = client.post("/v1/bvh/solve", json={**body, "bvh": spoilt}).json()
    assert out["rows_warning"].startswith(f"bvh: line {first + 9}: frame 9 holds {said}"), out
    assert out["bvh"].split("\n")[first + 8] == spoilt.split("\n")[first + 8]  # kept
    seen = client.post("/v1/bvh/inspect", json={"bvh": spoilt, "frame": 0}).json()
    assert seen["rows_warning"] == out["rows_warning"]
    r = client.post("/v1/bvh/solve", json={**body, "bvh": spoilt, "frame": 9})
    assert r.status_code == 422 and f"line {first + 9}" in r.json()["detail"], r.text
    for fine in ("1e7", "-10000000", "-9.35e-15", "0.123456789012"):
        seen = client.post(
            "/v1/bvh/inspect", json={"bvh": _spoilt_word(text, 9, 20, fine), "frame": 0}
        ).json()  # fmt: skip
        assert seen["rows_warning"] is None, (fine, seen["rows_warning"])


@pytest.mark.parametrize("beside", ["1.2.3", "1-2", "."])
def test_a_number_out_of_range_beside_a_word_no_number_is_still_named(
    client: Any, bvh_files: dict[str, Path], beside: str
) -> None:
    """An API audit: a ``1e400`` was named alone on its line, but not beside a word made of
    a number's characters that is none (``1.2.3``, which numpy does not read): the line was
    passed over whole. Now it is named the same way, before or after that word, and in a
    block of wrapped frames too."""
    from tests.core.test_bvh_write import relaid

    text = raw(bvh_files["bandai"])
    first = text.split("\n").index("MOTION") + 4  # frame 0's line, 1-based
    said = "'1e400', out of range (no finite number)"
    for column in (19, 21):  # the other word before and after it
        spoilt = _spoilt_word(_spoilt_word(text, 9, column, beside), 9, 20, "1e400")
        seen = client.post("/v1/bvh/inspect", json={"bvh": spoilt, "frame": 0}).json()
        warning = seen["rows_warning"]
        assert warning is not None and warning.startswith(
            f"bvh: line {first + 9}: frame 9 holds {said}"
        ), (column, warning)
        wrapped = relaid(spoilt, 11)
        bvh = parse_bvh(wrapped, frames=[0])
        got = odd_row(wrapped, bvh.motion_offset, 1, bvh.num_frames, bvh.num_channels, 1e7)
        assert got is not None and (got.frame, got.detail) == (9, said), (column, got)


@pytest.mark.parametrize("word", ["nan", "1,5", "1e400"])
def test_a_bad_value_in_a_wrapped_block_is_named(
    client: Any, bvh_files: dict[str, Path], word: str
) -> None:
    """A block of frames wrapped over lines (11 values a line, CRLF) was not looked at: a
    ``nan`` in a frame not read was answered without a word. Now its frame (its word's index
    over the channels) and its line are named, as in a block of one frame a line."""
    from tests.core.test_bvh_write import relaid

    text = relaid(raw(bvh_files["bandai"]), 11, "\r\n")
    bvh = parse_bvh(text, frames=[0])
    c = bvh.num_channels
    head = text[: bvh.motion_offset]
    words = text[bvh.motion_offset :].split()
    words[7 * c + 30] = word  # frame 7's value 30
    block = "\r\n".join(" ".join(words[i : i + 11]) for i in range(0, len(words), 11))
    spoilt = head + block + "\r\n"
    line = head.count("\n") + 1 + (7 * c + 30) // 11  # the word's line, 1-based
    body = {"frame": 0, "targets": [{"joint": "Hand_L", "position": [30.0, 100.0, 20.0]}]}
    out = client.post("/v1/bvh/solve", json={**body, "bvh": spoilt})
    assert out.status_code == 200, out.text
    warning = out.json()["rows_warning"]
    assert warning is not None and warning.startswith(f"bvh: line {line}: frame 7 holds '{word}'")
    assert out.json()["bvh"].endswith(block[block.index(word) :] + "\r\n")  # kept as sent
    clean = client.post("/v1/bvh/inspect", json={"bvh": text, "frame": 3}).json()
    assert clean["rows_warning"] is None


def test_a_line_of_several_frames_names_the_first_frames_fault() -> None:
    """Frames wrapped (here two on a line): of two faults on one line, the first word's
    frame is named, whatever the fault (a review found frame 1's ``nan`` named before frame
    0's ``1e400``, not-a-number faults being told first on a line)."""
    text = "X\n1 1e400 3 4 5 nan\n1 2 3 4 5 6\n"
    got = odd_row(text, 2, 10, 4, 3, 1e7)
    assert got == core.bvh_rows.OddRow(0, 10, "'1e400', out of range (no finite number)")
    got = odd_row("X\n1 2 nan 4 1e400 6\n1 2 3 4 5 6\n", 2, 10, 4, 3, 1e7)
    assert got == core.bvh_rows.OddRow(0, 10, "'nan', not a number")


@pytest.mark.parametrize("chunk", [64, 1000, 1 << 20])
def test_a_wrapped_block_s_frames_are_counted_over_chunks(
    bvh_files: dict[str, Path], chunk: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A wrapped block's words are counted across chunks: the frame named is the bad
    word's index over the channels, whatever the chunks."""
    from tests.core.test_bvh_write import relaid

    monkeypatch.setattr(core.bvh_rows, "_CHUNK", chunk)
    text = relaid(raw(bvh_files["bandai"]), 7)
    bvh = parse_bvh(text, frames=[0])
    head, words = text[: bvh.motion_offset], text[bvh.motion_offset :].split()
    first = head.count("\n") + 1
    for at in (0, 5, bvh.num_channels * 100 + 3, len(words) - 1):
        spoilt = list(words)
        spoilt[at] = "1e999"
        t = head + "\n".join(" ".join(spoilt[i : i + 7]) for i in range(0, len(words), 7))
        got = odd_row(t, bvh.motion_offset, first, bvh.num_frames, bvh.num_channels, 1e7)
        assert got is not None and got.frame == at // bvh.num_channels, (at, got)
        assert got.line == first + at // 7 and got.detail.startswith("'1e999'"), (at, got)


def test_a_block_of_exponents_is_read_by_numpy_not_word_by_word(
    bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Every value written with an exponent not negative (``1e+01``: some writers' ``%e``)
    makes every word one that may be past the bound: 8 MB of them were read a Python
    ``float`` a word, ~1.5 s; numpy reads them in one go (~0.15 s on a busy host)."""
    text = raw(bvh_files["bandai"])
    bvh = parse_bvh(text, frames=[0])
    c = bvh.num_channels
    rows = 8_000_000 // (6 * c)
    head = re.sub(r"Frames:\s*\d+", f"Frames: {rows}", text[: bvh.motion_offset])
    block = "\n".join(" ".join(["1e+01"] * c) for _ in range(rows))
    spoilt = head + block[:-5] + "1e400\n"
    first = head.count("\n") + 1
    read = _counted(monkeypatch, "fromstring", "_beyond")
    got = odd_row(spoilt, len(head), first, rows, c, 1e7)
    assert got is not None and got.frame == rows - 1 and got.detail.startswith("'1e400'"), got
    # one numpy read a chunk of ~1 MB, one word read alone: the one it names
    assert read == {"fromstring": len(spoilt) // (1 << 20) + 1, "_beyond": 1}, read


def test_a_block_with_spaces_past_ascii_is_looked_at_by_numpy(
    bvh_files: dict[str, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """A chunk holding a character past ASCII (a no-break space ending every line: a
    writer's, or an attacker's) was looked at word by word in Python, 2 s for 8 MB; now
    it is narrowed to ASCII (the same words, at the same places) and looked at as any
    chunk is. A value past ASCII (``５``) is still named, quoted as written."""
    text = raw(bvh_files["bandai"])
    bvh = parse_bvh(text, frames=[0])
    c = bvh.num_channels
    rows = 8_000_000 // (5 * c)
    head = re.sub(r"Frames:\s*\d+", f"Frames: {rows}", text[: bvh.motion_offset])
    lines = [" ".join(["0.5"] * c) + "\u00a0" for _ in range(rows)]
    first = head.count("\n") + 1
    lines[rows - 3] = lines[rows - 3].replace("0.5", "\uff15", 1)
    spoilt = head + "\n".join(lines) + "\n"
    read = _counted(monkeypatch, "_narrowed", "_odd_in")
    got = odd_row(spoilt, len(head), first, rows, c, 1e7)
    assert got == core.bvh_rows.OddRow(rows - 3, first + rows - 3, "'\uff15', not a number")
    # each chunk of ~1 MB narrowed by numpy and looked at as a whole
    chunks = len(spoilt) // (1 << 20) + 1
    assert read == {"_narrowed": chunks, "_odd_in": chunks}, read


@pytest.mark.parametrize("tail", ["x", ".1.1", "1e400"])
def test_a_long_word_of_digits_is_looked_at_in_linear_time(
    bvh_files: dict[str, Path], tail: str
) -> None:
    """A word no number is, read where numpy cannot read its chunk, is found by a pattern
    that backtracked over a run of digits: 16,000 digits and an ``x`` took 5 s, a word of
    a megabyte hours (a review of the fix above). Now a frame's value of 40,000 digits
    and ``tail`` (40-50 s before) is looked at in well under a second, and named where it
    is no number; a number of 40,000 digits is infinity."""
    import time

    text = raw(bvh_files["bandai"])
    spoilt = _spoilt_word(text, 9, 20, "1" * 40_000 + tail)
    bvh = parse_bvh(spoilt, frames=[0])
    first = spoilt.split("\n").index("MOTION") + 4
    t0 = time.perf_counter()
    got = odd_row(spoilt, bvh.motion_offset, first, bvh.num_frames, bvh.num_channels, 1e7)
    assert time.perf_counter() - t0 < 1.0
    if tail == "x":  # (not a number's character: named as such)
        assert got is not None and got.frame == 9 and got.detail.endswith("not a number")
    elif tail == "1e400":  # 1111...11e400: a number, past any float
        assert got is not None and got.frame == 9 and "out of range" in got.detail
    else:  # (a word of a number's characters that is none: not looked for)
        assert got is None
