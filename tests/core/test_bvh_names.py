"""A BVH joint's name is read as written (``core.bvh_words.Tokens.rest_of_line``): the
words after ROOT or JOINT on its line, up to a '{', with the blanks between them as they
are. Was: joined by one space, so that a file's ``Left  Hand`` or ``Right<TAB>Hand`` was
called ``Left Hand``/``Right Hand``, a name the file has not (an audit, 2026-12-06)."""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest

from core.bvh import MAX_NAME, BVHError, parse_bvh

#: names of a real file's joints as a user's tool may write them: blanks of every kind
#: Python splits words at, two in a row, and a '{' on the joint's own line
ODD = {
    "JOINT LeftHand\n": "JOINT Left  Hand\n",
    "JOINT RightHand\n": "JOINT Right\tHand\n",
    "JOINT LeftFoot\n": "JOINT Left \x0b\x85Foot\n",
    "JOINT RightFoot\n": "JOINT Right\u3000Foot \n",
}


def odd_names(text: str) -> str:
    """``text`` (AnimatedDrawings' fair1 ``dab.bvh``) with :data:`ODD`'s names and its
    Neck's '{' on the JOINT line."""
    for plain, odd in ODD.items():
        assert text.count(plain) == 1, plain
        text = text.replace(plain, odd)
    text, n = re.subn(r"JOINT Neck\n\s*\{", "JOINT Neck {", text)
    assert n == 1
    return text


def written(text: str) -> list[str]:
    """The joints' names as an independent reader finds them: each ROOT or JOINT line's
    text after the keyword, less blanks at either end and a '{' at its end."""
    out = []
    for line in re.split(r"\r\n|\r|\n", text.partition("MOTION")[0]):
        found = re.match(r"\s*(?:ROOT|JOINT)\s(.*)", line)
        if found:
            out.append(found.group(1).strip().removesuffix("{").strip())
    return out


@pytest.mark.parametrize("window", [1, 7, 64, 1 << 14])
def test_joint_names_are_read_as_written(
    bvh_files: dict[str, Path], window: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A real file with odd names: each read as written (wherever a window of the hierarchy
    is cut, even inside a name), its End Site named after it; the rest as it was."""
    from core import bvh_words

    monkeypatch.setattr(bvh_words, "WINDOW", window)
    plain = bvh_files["fair1-child-inches-zup"].read_text()
    text = odd_names(plain)
    before, after = parse_bvh(plain, "plain"), parse_bvh(text, "odd")
    names = [j.name for j in after.joints if not j.end_site]
    assert names == written(text)
    for name in ("Left  Hand", "Right\tHand", "Left \x0b\x85Foot", "Right\u3000Foot", "Neck"):
        assert name in names, name
    assert "Left  Hand_end" not in names  # (LeftHand has a joint LeftHandEnd, no End Site)
    ends = [j for j in after.joints if j.end_site]
    assert all(j.name == f"{after.joints[j.parent].name}_end" for j in ends)
    assert len(after.joints) == len(before.joints)
    for a, b in zip(before.joints, after.joints, strict=True):
        assert (a.parent, a.offset, a.channels) == (b.parent, b.offset, b.channels)
    assert after.motion.tobytes() == before.motion.tobytes()


@pytest.mark.parametrize("window", [1, 2, 5, 1 << 14])
def test_a_name_of_random_words_and_blanks_is_its_text(
    window: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Names of random words and blanks, the '{' on their line or the next: each is its
    line's text from its first word to its last."""
    from core import bvh_words

    monkeypatch.setattr(bvh_words, "WINDOW", window)
    rng = random.Random(window)
    blanks = " \t\x0b\x0c\x1c\x85\xa0\u2028\u3000"
    for _ in range(300):
        words = [rng.choice(["a", "Hand", "x" * 30, "é:b"]) for _ in range(rng.randint(1, 4))]
        gaps = ["".join(rng.choice(blanks) for _ in range(rng.randint(1, 3))) for _ in words]
        name = "".join(w + g for w, g in zip(words, gaps, strict=True)).rstrip(blanks)
        brace = rng.choice([" {", "\n{", "\r\n\t{", "\t{"])
        text = (
            f"HIERARCHY\nROOT {name}{brace}\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n"
            "End Site\n{\nOFFSET 0 1 0\n}\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n"
        )
        bvh = parse_bvh(text, "t")
        assert [j.name for j in bvh.joints] == [name, f"{name}_end"], repr(text)


def test_a_name_longer_than_max_name_as_written_is_refused() -> None:
    """The limit holds for the name as written (blanks counted), as the character form's
    limit on a joint's name does: a name the service reads, it can be given back."""
    tail = "\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 1\nFrame Time: 0.1\n0\n"
    fits = "a" + " " * (MAX_NAME - 2) + "b"
    assert parse_bvh(f"HIERARCHY\nROOT {fits}{tail}").joints[0].name == fits
    with pytest.raises(BVHError, match=f"line 2: a joint name of more than {MAX_NAME}"):
        parse_bvh(f"HIERARCHY\nROOT a {fits}{tail}")
