"""A character named as another studio or tool names its joints is found automatically.

A real Bandai-Namco file (tests/character_files.py) is renamed joint by joint into the names
of each naming scheme of ``core.characters_maps.SCHEMES`` that no shared file uses (Xsens,
Rokoko, 3ds Max Biped, SMPL, DAZ Genesis 8 and 9, Character Creator, SOMA, Azure Kinect, HumanIK's
``Character1_``, Unity's humanoid names, Xsens's BVH export): the map must pick that
scheme, and an edit of the renamed file must write exactly the frame values the original's
does (the same joints anchor the same points).
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from core.bvh import parse_bvh
from core.bvh_write import skeleton_of
from core.characters_maps import resolve_map
from service.bvh_models import BVHSolveRequest
from service.character_bvh import bvh_answer, character_from_bvh, read_request_bvh
from service.characters import character_problem, solve_prepared
from service.engine import Engine
from tests.character_files import FILES

#: Bandai-Namco's names, canonical order (centre, then limbs with "{s}" for L / R)
_BANDAI = ["Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_{s}", "UpperArm_{s}", "LowerArm_{s}",
           "Hand_{s}", "UpperLeg_{s}", "LowerLeg_{s}", "Foot_{s}", "Toes_{s}"]  # fmt: skip
#: scheme -> (the same joints' names, left / right tokens); names as the research of
#: 2026-12-04 found them in real files and exporters (see docs/characters.md)
_RENAMED: dict[str, tuple[str, tuple[str, str]]] = {
    "xsens": ("Pelvis L3 T8 Neck Head {s}Shoulder {s}UpperArm {s}ForeArm {s}Hand {s}UpperLeg "
              "{s}LowerLeg {s}Foot {s}Toe", ("Left", "Right")),
    "rokoko": ("Hips Spine1 Spine4 Neck Head {s}Shoulder {s}Arm {s}ForeArm {s}Hand {s}Thigh "
               "{s}Shin {s}Foot {s}Toe", ("Left", "Right")),
    "biped": ("Bip01|Pelvis Bip01|Spine Bip01|Spine2 Bip01|Neck Bip01|Head Bip01|{s}|Clavicle "
              "Bip01|{s}|UpperArm Bip01|{s}|Forearm Bip01|{s}|Hand Bip01|{s}|Thigh "
              "Bip01|{s}|Calf Bip01|{s}|Foot Bip01|{s}|Toe0", ("L", "R")),
    "smpl": ("m_avg_Pelvis m_avg_Spine1 m_avg_Spine3 m_avg_Neck m_avg_Head m_avg_{s}_Collar "
             "m_avg_{s}_Shoulder m_avg_{s}_Elbow m_avg_{s}_Wrist m_avg_{s}_Hip m_avg_{s}_Knee "
             "m_avg_{s}_Ankle m_avg_{s}_Foot", ("L", "R")),
    "cmu-daz": ("hip abdomenLower chestUpper neckLower head {s}Collar {s}ShldrBend "
                "{s}ForearmBend {s}Hand {s}ThighBend {s}Shin {s}Foot {s}Toe", ("l", "r")),
    "daz-genesis9": ("hip spine1 spine4 neck1 head {s}_shoulder {s}_upperarm {s}_forearm "
                     "{s}_hand {s}_thigh {s}_shin {s}_foot {s}_toes", ("l", "r")),
    "character-creator": ("CC_Base_Hip CC_Base_Waist CC_Base_Spine02 CC_Base_NeckTwist01 "
                          "CC_Base_Head CC_Base_{s}_Clavicle CC_Base_{s}_Upperarm "
                          "CC_Base_{s}_Forearm CC_Base_{s}_Hand CC_Base_{s}_Thigh "
                          "CC_Base_{s}_Calf CC_Base_{s}_Foot CC_Base_{s}_ToeBase", ("L", "R")),
    "vrm": ("Hips Spine UpperChest Neck Head {s}Shoulder {s}UpperArm {s}LowerArm {s}Hand "
            "{s}UpperLeg {s}LowerLeg {s}Foot {s}Toes", ("Left", "Right")),  # Unity's
    "cmu-asf-bvh": ("Hips Chest Chest4 Neck Head {s}Collar {s}Shoulder {s}Elbow {s}Wrist "
                    "{s}Hip {s}Knee {s}Ankle {s}Toe", ("Left", "Right")),  # Xsens MVN BVH
    "soma": ("Hips Spine1 Chest Neck1 Head {s}Shoulder {s}Arm {s}ForeArm {s}Hand {s}Leg {s}Shin "
             "{s}Foot {s}ToeBase", ("Left", "Right")),
    "azure-kinect": ("K4ABT_JOINT_PELVIS K4ABT_JOINT_SPINE_NAVEL K4ABT_JOINT_SPINE_CHEST "
                     "K4ABT_JOINT_NECK K4ABT_JOINT_HEAD K4ABT_JOINT_CLAVICLE_{s} "
                     "K4ABT_JOINT_SHOULDER_{s} K4ABT_JOINT_ELBOW_{s} K4ABT_JOINT_WRIST_{s} "
                     "K4ABT_JOINT_HIP_{s} K4ABT_JOINT_KNEE_{s} K4ABT_JOINT_ANKLE_{s} "
                     "K4ABT_JOINT_FOOT_{s}", ("LEFT", "RIGHT")),
    "mixamo": ("Character1_Hips Character1_Spine Character1_Spine2 Character1_Neck "
               "Character1_Head Character1_{s}Shoulder Character1_{s}Arm Character1_{s}ForeArm "
               "Character1_{s}Hand Character1_{s}UpLeg Character1_{s}Leg Character1_{s}Foot "
               "Character1_{s}ToeBase", ("Left", "Right")),
}  # fmt: skip


def _renamed(text: str, scheme: str) -> str:
    """The file with each of Bandai-Namco's joints named as ``scheme`` names it (a "|" in a
    name is a space: Biped's names hold spaces), the root too where HumanIK prefixes all."""
    names, sides = _RENAMED[scheme]
    table: dict[str, str] = {}
    for old, new in zip(_BANDAI, [n.replace("|", " ") for n in names.split()], strict=True):
        if "{s}" in old:
            for bandai_side, side in zip(("L", "R"), sides, strict=True):
                table[old.replace("{s}", bandai_side)] = new.replace("{s}", side)
        else:
            table[old] = new
    if scheme == "mixamo":
        table["joint_Root"] = "Character1_Reference"

    def swap(m: re.Match[str]) -> str:
        return f"{m.group(1)}{table.get(m.group(2), m.group(2))}"

    return re.sub(r"^(\s*(?:ROOT|JOINT) )(.+?)\s*$", swap, text, flags=re.MULTILINE)


def _edit(engine: Engine, text: str, names: dict[str, str]) -> Any:
    """The written frame and report of a head moved 8 cm forward and down with both ankles
    pinned (soft reach), on the file's test frame."""
    _, _, _, frame = FILES["bandai"]
    target: dict[str, Any] = {"joint": "head", "position": [0.0, 0.0, 0.0]}
    body = {"bvh": text, "frame": frame, "targets": [target],
            "pins": ["left_ankle", "right_ankle"], "options": {"reach": "soft"}}  # fmt: skip
    bvh = read_request_bvh(text)
    req = BVHSolveRequest.model_validate(body)
    ch = character_from_bvh(bvh, req, req.frame)
    start = character_problem(ch, req)
    head = ch.from_service(start.pose[start.target_idx[0]][None])[0]
    target["position"] = [float(head[0]), float(head[1]) - 8.0, float(head[2]) + 8.0]
    req = BVHSolveRequest.model_validate(body)
    edit = solve_prepared(engine, ch, character_problem(ch, req))
    out = bvh_answer(bvh, ch, req, edit)
    written = out["bvh"].split("MOTION", 1)[1].splitlines()[3 + frame]
    changed = [names.get(j, j) for j in out["changed_joints"]]
    return written, changed, [t["error"] for t in out["targets"] + out["pins"]]


@pytest.fixture(scope="module")
def bandai(bvh_files: dict[str, Path]) -> str:
    return bvh_files["bandai"].read_text()


@pytest.mark.parametrize("scheme", list(_RENAMED))
def test_a_renamed_real_file_maps_to_its_scheme_and_solves_alike(
    engine: Engine, bandai: str, scheme: str
) -> None:
    text = _renamed(bandai, scheme)
    skel = skeleton_of(parse_bvh(text))
    jmap = resolve_map(skel)
    assert jmap.scheme == scheme, jmap.describe()
    original = skeleton_of(parse_bvh(bandai))
    ref = resolve_map(original)
    assert [a.joint for a in jmap.anchors] == [a.joint for a in ref.anchors]
    back = dict(zip(skel.names, original.names, strict=True))  # renamed -> Bandai-Namco's
    got = _edit(engine, text, back)
    assert got[1] and got[0] != bandai.split("MOTION", 1)[1].splitlines()[3 + FILES["bandai"][3]]
    assert got == _edit(engine, bandai, {})
