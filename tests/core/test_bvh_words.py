"""``core.bvh_words.BVHError`` as a caller in another process or thread pool gets it: a
reader's error on a real file, cut short, pickled and read back whole."""

from __future__ import annotations

import multiprocessing
import pickle
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest

from core.bvh import BVHError, parse_bvh, read_bvh


def _cut(bvh_files: dict[str, Path], tmp_path: Path) -> Path:
    """The Bandai walk cut in the middle of its HIERARCHY (a truncated upload)."""
    text = bvh_files["bandai"].read_text()
    cut = tmp_path / "walk_cut.bvh"
    cut.write_text(text[: text.index("MOTION") // 2])
    return cut


def _same(got: BVHError, want: BVHError) -> None:
    assert type(got) is BVHError
    assert str(got) == str(want) and got.args == want.args
    assert (got.file, got.reason) == (want.file, want.reason)
    assert vars(got) == vars(want)


def test_a_bvh_error_survives_pickling(bvh_files: dict[str, Path], tmp_path: Path) -> None:
    """``BVHError(file, reason)`` passed ``args`` its one message, which ``__init__`` does
    not take: unpickling it was ``TypeError: missing 1 required positional argument:
    'reason'``. Now it comes back as it was, its fields and any set on it since."""
    cut = _cut(bvh_files, tmp_path)
    with pytest.raises(BVHError) as info:
        read_bvh(cut)
    err = info.value
    assert err.file == str(cut) and str(err) == f"{cut}: {err.reason}"
    _same(pickle.loads(pickle.dumps(err)), err)
    with pytest.raises(BVHError) as text_info:  # the service's reader: a request's text
        parse_bvh(cut.read_text(), "bvh")
    text_info.value.__notes__ = ["read by a worker"]  # (state set after it was raised)
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        _same(pickle.loads(pickle.dumps(text_info.value, protocol)), text_info.value)


def test_a_bvh_error_raised_in_a_worker_process_reaches_the_caller(
    bvh_files: dict[str, Path], tmp_path: Path
) -> None:
    """A process pool pickles a worker's exception back to the caller: the error unpickled
    there, not a ``BrokenProcessPool`` (the pool's result thread died unpickling it)."""
    cut = _cut(bvh_files, tmp_path)
    with pytest.raises(BVHError) as here:
        read_bvh(cut)
    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(1, mp_context=ctx) as pool, pytest.raises(BVHError) as there:
        pool.submit(read_bvh, cut).result(timeout=120)
    _same(there.value, here.value)


def test_the_k_th_newline_is_found_wherever_it_lies() -> None:
    """``after_newlines`` (a frame's line found by counting newlines: spans doubling from
    where the last frame read stands, a bisection, then steps) lands where stepping over
    ``k`` newlines one at a time lands: near and far, on lines short and long, from the
    text's start or a line's, with and without a final newline."""
    import random

    from core.bvh_words import after_newlines

    rng = random.Random(1)
    for _ in range(2000):
        lines = ["x" * rng.choice([0, 3, 80, 900, 2500]) for _ in range(rng.randint(0, 300))]
        text = "\n".join(lines) + ("\n" if rng.random() < 0.5 else "")
        at = 0
        for _ in range(rng.randint(0, text.count("\n"))):
            at = text.find("\n", at) + 1
        k = rng.randint(0, text.count("\n", at))
        want = at
        for _ in range(k):
            want = text.find("\n", want) + 1
        assert after_newlines(text, at, k) == want, (len(text), at, k)


@pytest.mark.parametrize("head", ["", "\ufeff", "\n\n  \n"])
def test_a_file_with_nothing_before_motion_is_no_bvh_file(
    bvh_files: dict[str, Path], head: str
) -> None:
    """A file whose MOTION section comes first (its HIERARCHY lost) was "unexpected end of
    HIERARCHY, expected 'HIERARCHY'" (an API audit, 2026-12-07): it has none."""
    text = bvh_files["bandai"].read_text()
    with pytest.raises(BVHError) as caught:
        parse_bvh(head + text[text.index("MOTION") :], "walk.bvh")
    said = str(caught.value)
    assert said.startswith("walk.bvh: not a BVH file (no HIERARCHY keyword)"), said
    assert "unexpected end" not in said, said


@pytest.mark.parametrize("cut", [1, 2, 5])
@pytest.mark.parametrize("ends", ["\n", "\r\n", "\r"])
def test_a_hierarchy_that_ends_unclosed_at_its_motion_line_names_the_line(
    bvh_files: dict[str, Path], cut: int, ends: str
) -> None:
    """A hierarchy whose last lines are lost before its MOTION line (a '}' or a joint
    deleted by hand) names the MOTION line, where it ends unclosed, as every other fault of
    a file names its line (docs/bvh.md); it was "unexpected end of HIERARCHY, expected
    JOINT, End Site or '}'" alone (an API audit, 2026-12-07). Short hierarchies (shared,
    read from their own text) and long ones (read in place) alike."""
    text = bvh_files["bandai"].read_text()
    lines = text.split("\n")
    motion = lines.index("MOTION")
    kept = lines[: motion - cut] + lines[motion:]
    line = motion - cut + 1  # the MOTION line's number, 1-based
    for pad in (0, 1 << 17):  # (past core.bvh.SHARED_TEXT: not shared)
        body = (ends.join(kept)).replace("HIERARCHY", "HIERARCHY" + " " * pad, 1)
        with pytest.raises(BVHError) as caught:
            parse_bvh(body, "walk.bvh", frames=[0])
        said = str(caught.value)
        assert said.startswith(f"walk.bvh: line {line}: unexpected end of HIERARCHY"), said
        assert "where its MOTION line begins" in said, said
