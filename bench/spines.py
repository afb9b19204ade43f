"""Pins on characters whose spine has more joints than the canonical one:
``python -m bench.spines [--extra 0 --extra 3 ...] [--goals 12]``.

A rig with a long spine (Unreal's five, a Rigify or a DAZ figure's more) maps its pelvis,
spine1 and chest onto three of them; the joints between keep their own turns, and the polish
that puts the answer onto the character's own bones turns them (docs/characters.md, "Long
spines"). Until 2026-12-06 that polish drifted off true rotations on such spines, and pinned
wrists ended 5-104 mm off (an audit's D1).

Here the character is a real file's skeleton and frame (CMU salsa 01, frame 300, cmu-daz
names, cm; out of ``--mocap``) with ``extra`` joints spliced in between ``abdomen``
(spine1) and ``chest`` (:func:`long_spine`); each edit drags the head to a seeded goal with
both ankles and both wrists pinned, in exact and in soft reach, through the BVH form and
the JSON character form (their steps in process, as the routes take them). Per spine: the
edits that leave a pin more than 1 mm off (the default tolerance) and the worst pin, as
measured on what each answer returns (the BVH form: its report, measured on the file as
written; the JSON form: forward kinematics of the rotations it returns).
"""

from __future__ import annotations

import dataclasses
import subprocess
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

from core.bvh import BVH, BVHJoint, parse_bvh
from core.bvh_write import format_bvh, pose_of, skeleton_of
from core.characters import Pose, forward_kinematics, matrix_to_quat, quat_to_matrix
from core.characters_maps import resolve_map
from core.retarget import canonical_points
from core.skeleton import JOINT_INDEX

if TYPE_CHECKING:  # pragma: no cover
    from service.characters import Character

#: The file the characters are made of: (archive, member, frame).
SOURCE = ("cmu-dance.tar.xz", "train_data_bvh/salsa/01.bvh", 300)
PINS = ["left_ankle", "right_ankle", "left_wrist", "right_wrist"]


def long_spine(text: str, frame: int, extra: int, degrees: float, seed: int = 0) -> str:
    """A one-frame BVH of ``text``'s frame ``frame`` with ``extra`` joints (3 rotation
    channels, the chest's order) between the chest (the map's spine2) and its parent: the
    chest's offset split into ``extra + 1`` equal parts, each new joint turned up to
    ``degrees`` about each axis (seeded)."""
    bvh = parse_bvh(text)
    chest = resolve_map(skeleton_of(bvh)).anchors[JOINT_INDEX["spine2"]].joint
    cj = bvh.joints[chest]
    rot = tuple(c for c in cj.channels if c.lower().endswith("rotation"))
    part = (cj.offset[0] / (extra + 1), cj.offset[1] / (extra + 1), cj.offset[2] / (extra + 1))
    joints: list[BVHJoint] = []
    index: dict[int, int] = {-1: -1}
    shift = 0
    for i, j in enumerate(bvh.joints):
        parent = index[j.parent]
        if i == chest:
            for k in range(extra):
                joints.append(
                    BVHJoint(f"SpineExtra{k}", parent, part, rot, j.channel_start + shift)
                )
                parent = len(joints) - 1
                shift += len(rot)
        index[i] = len(joints)
        offset = part if i == chest else j.offset
        start = j.channel_start + shift
        joints.append(dataclasses.replace(j, parent=parent, offset=offset, channel_start=start))
    row = bvh.row(frame)
    turns = np.random.default_rng(seed).uniform(-degrees, degrees, extra * len(rot))
    cut = cj.channel_start
    motion = np.concatenate([row[:cut], turns, row[cut:]])[None]
    return format_bvh(BVH(bvh.name, tuple(joints), bvh.frame_time, motion))


def head_goals(text: str, n: int, seed: int = 7) -> list[list[float]]:
    """``n`` seeded head goals of the one-frame file ``text`` (its units): the head moved by
    up to about half the pelvis-head distance, so that the polish runs its steps."""
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    pts = canonical_points(skel, pose_of(bvh, 0), resolve_map(skel))
    head = pts[JOINT_INDEX["head"]]
    trunk = float(np.linalg.norm(head - pts[JOINT_INDEX["pelvis"]]))
    rng = np.random.default_rng(seed)
    return [(head + rng.normal(0.0, 0.6 * trunk, 3)).tolist() for _ in range(n)]


def edits(goals: list[list[float]]) -> list[dict[str, Any]]:
    """Each goal with both ankles and wrists pinned, in exact then soft reach."""
    return [
        {"targets": [{"joint": "head", "position": g}], "pins": PINS, "options": {"reach": r}}
        for g in goals
        for r in ("exact", "soft")
    ]


def character_body(text: str) -> dict[str, Any]:
    """The JSON character form of the one-frame file ``text`` (cm)."""
    bvh = parse_bvh(text)
    skel = skeleton_of(bvh)
    pose = pose_of(bvh, 0)
    joints = [
        {"name": n, "parent": None if p < 0 else skel.names[p], "offset": list(o)}
        for n, p, o in zip(skel.names, skel.parents, skel.offsets.tolist(), strict=True)
    ]
    return {
        "character": {"joints": joints, "units": "cm"},
        "rotations": dict(zip(skel.names, matrix_to_quat(pose.rotations).tolist(), strict=True)),
        "root_position": pose.translations[skel.parents.index(-1)].tolist(),
    }


def worst_pins(text: str, goals: list[list[float]], models: Path) -> dict[str, list[float]]:
    """Per form (``bvh``, ``json``) each edit's worst pin (m), as its answer reports it."""
    from service.bvh_models import BVHSolveRequest
    from service.character_bvh import bvh_answer, character_from_bvh, read_request_bvh
    from service.characters import (
        CharacterSolveRequest,
        character_answer,
        character_from_request,
        character_problem,
        solve_prepared,
    )
    from service.engine import Engine

    engine = Engine(models)
    bvh = read_request_bvh(text)
    base = character_body(text)
    out: dict[str, list[float]] = {"bvh": [], "json": []}
    for body in edits(goals):
        req = BVHSolveRequest.model_validate({"bvh": text, "frame": 0, **body})
        ch = character_from_bvh(bvh, req, req.frame)
        answer = bvh_answer(bvh, ch, req, solve_prepared(engine, ch, character_problem(ch, req)))
        out["bvh"].append(max(p["error"] for p in answer["pins"]))
        jreq = CharacterSolveRequest.model_validate({**base, **body})
        jch = character_from_request(jreq)
        edit = solve_prepared(engine, jch, character_problem(jch, jreq))
        answer = character_answer(jch, edit, jreq.rotations)
        out["json"].append(_pins_of_rotations(jch, answer))
    return out


def _pins_of_rotations(ch: Character, answer: dict[str, Any]) -> float:
    """The worst pin (m) of a JSON answer, measured on the rotations it returns (the
    report is measured on the pose they were taken from: it held the pins while the
    rotations, drifted off true rotations, did not)."""
    skel = ch.skel
    rotations = quat_to_matrix([answer["rotations"][n] for n in skel.names])
    translations = ch.pose.translations.copy()
    translations[skel.parents.index(-1)] = answer["root_position"]
    now = ch.jmap.points(*forward_kinematics(skel, Pose(rotations, translations)))
    then = ch.jmap.points(*forward_kinematics(skel, ch.pose))
    at = [JOINT_INDEX[p] for p in PINS]
    return float(np.linalg.norm(ch.to_service(now)[at] - ch.to_service(then)[at], axis=1).max())


def main(
    extra: Annotated[
        list[int] | None, typer.Option(help="Joints spliced in (repeat); default 0 3 5 8 20.")
    ] = None,
    goals: Annotated[int, typer.Option(min=1, help="Head goals per spine.")] = 12,
    mocap: Annotated[Path, typer.Option(help="The archives.")] = Path("../shared/mocap"),
    models: Annotated[Path, typer.Option(help="Models folder.")] = Path("models"),
) -> None:
    """Pins on long spines: a markdown table (see the module)."""
    archive, member, frame = SOURCE
    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(["tar", "-xJf", str(mocap / archive), "-C", tmp, member], check=True)
        text = (Path(tmp) / member).read_text()
    typer.echo("| joints spliced in | form | edits with a pin > 1 mm | worst pin (mm) |")
    typer.echo("|---|---|---|---|")
    for n in extra or [0, 3, 5, 8, 20]:
        spine = long_spine(text, frame, n, 5.0)
        misses = worst_pins(spine, head_goals(spine, goals), models)
        for form, worst in misses.items():
            mm = np.asarray(worst) * 1e3
            typer.echo(f"| {n} | {form} | {int((mm > 1.0).sum())} of {mm.size} | {mm.max():.2f} |")


if __name__ == "__main__":
    typer.run(main)
