"""``core.text``'s "did you mean" hint: a case slip or a typo of a name suggests it, and the
spelling comparison is bounded."""

from __future__ import annotations

import difflib

import pytest

from core.text import SPELLING_WORK, did_you_mean, near_name


def test_a_case_slip_or_a_typo_names_the_joint_meant() -> None:
    names = ["Hips", "Spine", "UpperArm_L", "UpperArm_R", "Foot_L"]
    assert did_you_mean("hips", names) == " (did you mean 'Hips'?)"
    assert did_you_mean("UpperArm_LL", names) == " (did you mean 'UpperArm_L'?)"
    assert did_you_mean("tail", names) == ""


def test_a_big_skeleton_is_matched_for_case_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    """Past ``SPELLING_WORK`` characters compared, spellings are not (difflib is pure
    Python: 8 names of 97 characters against 2,000 joints of 96 took 1.5 s of a request,
    a review); a name off by case alone is still found."""
    names = [f"{'segment_' * 11}{i:08d}" for i in range(2000)]
    assert len(names[0]) * sum(map(len, names)) > SPELLING_WORK

    def refused(*args: object, **kwargs: object) -> list[str]:
        raise AssertionError("spellings compared")

    monkeypatch.setattr(difflib, "get_close_matches", refused)
    assert did_you_mean(names[7].upper(), names) == f" (did you mean '{names[7]}'?)"
    assert did_you_mean(names[7] + "x", names) == ""


def test_near_name_offers_a_slip_s_name_once_and_never_a_neighbour() -> None:
    """:func:`core.text.near_name`, the one rule for every name a request gives: the same
    name but for case, dashes and blanks (offered as the candidates spell it), else one
    alone nearest by spelling; not a neighbour, not a tie."""
    names = ["LeftHand", "RightHand", "Left  Foot", "spine1", "spine2"]
    assert near_name("lefthand", names) == "LeftHand"
    assert near_name("LeftHnad", names) == "LeftHand"
    assert near_name("left foot", names) == "Left  Foot"
    assert near_name("left-foot", names) == "Left  Foot"
    assert near_name("spine3", names) is None  # (spine1 and spine2 tie)
    assert near_name("Hips", names) is None
    assert near_name("x" * 300, ["x" * 299] * 1) == "x" * 299  # (within SPELLING_WORK)
    assert near_name("y" * 300, ["x" * 1000] * 1000) is None  # past it: case alone
