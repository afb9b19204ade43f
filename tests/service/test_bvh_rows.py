"""A malformed row in a frame the service does not read is told of (``rows_warning``).

The service parses only the frames it edits or inspects; an audit (2026-12-07) sent the
FAIR child's file with frame 5's row one value short (83 of 84), one long, and a ``nan``
on frame 7, edited frame 0, and got 200 with ``cut_short: null`` and no word. Now solve,
batch and inspect name the first such row's line and frame; the answer is as before.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
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


def test_odd_row_costs_milliseconds_a_megabyte(bvh_files: dict[str, Path]) -> None:
    """The look is no parse: CMU salsa's 2.9 MB in tens of milliseconds at most (~4 ms a
    MB measured; the whole read of the file takes 74)."""
    text = raw(bvh_files["cmu-daz-salsa"])
    bvh = parse_bvh(text, frames=[0])
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        assert odd_row(bvh.text, bvh.motion_offset, 1, bvh.num_frames, bvh.num_channels) is None
        best = min(best, time.perf_counter() - t0)
    assert best < 0.05, best
