"""What a build tells of its maps: checks of ``pose-trainer dataset``.

- maps against the mocap they read: a source not found, include globs that select no file
  of an archive, a source joint name in none of a map's files (a build failure), files a map
  lost, override / holdout globs that match nothing, a map without a licence;
- one limb's left and right joints crossed by a map (:func:`crossed_limb_errors`, a build
  failure);
- poses against plausible bodies (:func:`sanity_warnings`): per source, per actor and per
  take (one file), the thigh's length (the unit), the head over the pelvis (the up axis),
  the floor and the pelvis height (the root position), the toes ahead of the ankles (the
  sides); the train split's mean bone lengths (training's own test).
"""

from __future__ import annotations

import re
from collections import Counter, defaultdict
from collections.abc import Iterable, Iterator, Sequence
from itertools import pairwise
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np
import numpy.typing as npt

from core.skeleton import (
    BONE_CHILDREN,
    BONE_PARENTS,
    JOINT_INDEX,
    JOINT_NAMES,
    MIRROR,
    bone_lengths,
)
from core.text import close_match
from trainer.data.asf import CMU_FPS
from trainer.data.dataset import PoseDataset
from trainer.data.maps import MocapMap, did_you_mean, glob_to_regex

if TYPE_CHECKING:
    from trainer.data.build import ClipResult

#: Example paths shown when a map's globs match nothing.
EXAMPLES = 3

# --------------------------------------------------------------------------- sources


def _examples(m: MocapMap, files: Sequence[str]) -> list[str]:
    """A few of ``files``, those with the include globs' extension first."""
    suffixes = {Path(g).suffix for g in m.include} - {""}
    like = [f for f in files if Path(f).suffix in suffixes]
    return (like or list(files))[:EXAMPLES]


def _holds(m: MocapMap, files: Sequence[str]) -> str:
    if not files:
        return "; it holds no file"
    return f"; it holds {len(files)} files, e.g. {', '.join(_examples(m, files))}"


def _top_folder_hint(m: MocapMap, files: Sequence[str]) -> str:
    """A hint when every file sits under one top folder that the globs leave out."""
    tops = {f.split("/", 1)[0] if "/" in f else "" for f in files}
    if len(tops) != 1 or "" in tops:
        return ""
    top = tops.pop()
    if not any(m.selects(f.split("/", 1)[1]) for f in files):
        return ""
    return (
        f"; its files sit under a top folder '{top}/': the map's globs and [metadata] "
        f"pattern are relative to the archive root, so start them with '{top}/' (e.g. "
        f"include = ['{top}/{m.include[0]}']) or pack the archive from inside '{top}/'"
    )


def case_only(m: MocapMap, files: Sequence[str]) -> list[str]:
    """The files the map's include globs would select but for letter case (``x.BVH`` for
    ``*.bvh``; globs are case-sensitive), those its exclude globs leave out either way
    left out."""
    include = [re.compile(glob_to_regex(g).pattern, re.IGNORECASE) for g in m.include]
    exclude = [re.compile(glob_to_regex(g).pattern, re.IGNORECASE) for g in m.exclude]
    return [
        f
        for f in files
        if any(r.match(f) for r in include)
        and not any(r.match(f) for r in exclude)
        and not m.selects(f)
    ]


def _case_hint(m: MocapMap, files: Sequence[str]) -> str:
    miss = case_only(m, files)
    if not miss:
        return ""
    return (
        f"; {len(miss)} of them match ignoring letter case (e.g. {miss[0]!r}): globs are "
        "case-sensitive, so write the include globs as the files are named"
    )


def no_match_message(m: MocapMap, where: str, files: Sequence[str]) -> str:
    """An archive or folder found for a map whose include globs select none of its files."""
    globs = f"include {list(m.include)}" + (f" (exclude {list(m.exclude)})" if m.exclude else "")
    return (
        f"map {m.path}: {globs} matches no file in {where}"
        f"{_holds(m, files)}{_case_hint(m, files)}{_top_folder_hint(m, files)}"
    )


def case_warnings(m: MocapMap, files: Sequence[str]) -> list[str]:
    """Files the map leaves unread only for letter case (``.BVH`` beside ``.bvh`` takes):
    they went out of the dataset without a word."""
    miss = case_only(m, files)
    if not miss:
        return []
    return [
        f"map {m.path}: {len(miss)} file(s) match include {list(m.include)} only ignoring "
        f"letter case, e.g. {miss[0]!r}: not read (globs are case-sensitive: add a glob "
        "for them)"
    ]


def not_found_message(m: MocapMap, mocap_dir: Path, taken: Iterable[str] = ()) -> str:
    """A map whose archive (or extracted folder) is not in the mocap folder: what was looked
    for, and a close name if there is one (not one of ``taken``: other maps' archives)."""
    entries = sorted(p.name for p in mocap_dir.iterdir()) if mocap_dir.is_dir() else []
    entries = [e for e in entries if e not in set(taken)]
    globs = f"include {list(m.include)}"
    if m.archive is None:
        return (
            f"map {m.path}: source {m.source!r} has no `archive` and no file in {mocap_dir} "
            f"matches its {globs}"
        )
    hint = did_you_mean(m.archive, entries)
    if hint.lower().endswith(".zip'?"):  # (the builder reads tar archives and folders)
        hint += f" A zip is not read: repack it as .tar.xz or unzip it into '{m.archive_stem}/'."
    return (
        f"map {m.path}: source {m.source!r}: no archive {m.archive!r} nor folder "
        f"'{m.archive_stem}/' in {mocap_dir} (nor files matching its {globs} there){hint}"
    )


# --------------------------------------------------------------------------- map vs files


def unused_glob_warnings(m: MocapMap, selected: Sequence[str]) -> list[str]:
    """Override and holdout globs that match none of the map's selected files (a typo
    leaves their settings, or the held-out bodies, silently out); an override's split on
    files the map holds out (the holdout wins)."""
    out = []

    def unused(glob: str) -> str | None:
        regex = glob_to_regex(glob)
        if any(regex.match(f) for f in selected):
            return None
        near = close_match(glob, selected)
        return f" (a close file: {near!r})" if near else ""

    for i, o in enumerate(m.overrides):
        if (hint := unused(o.glob)) is not None:
            out.append(
                f"map {m.path}: [[override]] #{i + 1} glob {o.glob!r} matches none of its "
                f"{len(selected)} selected files: its settings are unused{hint}"
            )
    for glob in m.holdout:
        if (hint := unused(glob)) is not None:
            out.append(
                f"map {m.path}: holdout glob {glob!r} matches none of its {len(selected)} "
                f"selected files: it holds nothing out{hint}"
            )
    for i, o in enumerate(m.overrides):  # held out wins: a split asked there is unused
        regex = glob_to_regex(o.glob)
        held = [f for f in selected if regex.match(f) and m.is_holdout(f)]
        if o.get("split") is not None and held:
            out.append(
                f"map {m.path}: [[override]] #{i + 1} puts {len(held)} file(s) in split "
                f"{o.get('split')!r} that the map holds out (e.g. {held[0]!r}): held out "
                "they stay"
            )
    return out


def licence_warning(m: MocapMap) -> str | None:
    """A map without a licence: the data's licence is a term of the models trained on it."""
    if m.licence.strip():
        return None
    return (
        f"map {m.path}: no `licence` for source {m.source!r}: the data's licence becomes a "
        'term of the models trained on it (their manifest lists it); add licence = "..."'
    )


def amc_rate_warning(m: MocapMap, selected: Sequence[str]) -> str | None:
    """An ASF/AMC map that leaves the frame rate of some of the AMC files it selects to
    CMU's 120 Hz: AMC files carry none, and a studio's own at another rate was read at 120
    without a word (a studio audit, 2026-12-07)."""
    if m.reader != "asf":
        return None
    unset = [f for f in selected if f.lower().endswith(".amc") and m.fps_for(f, -1.0) < 0]
    if not unset:
        return None
    return (
        f"map {m.path}: {len(unset)} AMC file(s) read at {CMU_FPS:g} Hz, CMU's rate, as no "
        f"`fps` is set for them (AMC files carry no frame rate; the first: {unset[0]}): set "
        'yours with an [[override]], e.g. glob = "**", fps = 60'
    )


def missing_joint_errors(results: Sequence[ClipResult]) -> list[str]:
    """A source joint name (a map's, or an override's) that none of the files using it
    has: a typo, not a bad file. One message per name; [] if none."""
    by_map: dict[str, list[ClipResult]] = defaultdict(list)
    for r in results:
        if r.checked:
            by_map[r.job.map.path].append(r)
    out = []
    for rs in by_map.values():
        m = rs[0].job.map
        need = Counter(
            n for r in rs for n in {n for j in m.joints_for(r.job.relpath) for n in j.names}
        )
        lack = Counter(n for r in rs for n in r.missing)
        for name, count in sorted(lack.items()):
            if count < need[name]:
                continue
            hints = Counter(r.missing[name] for r in rs if r.missing.get(name))
            hint = f"; did you mean {hints.most_common(1)[0][0]!r}?" if hints else ""
            files = f"its {count} files" if count == len(rs) else f"the {count} files using it"
            out.append(f"map {m.path}: {m.joint_ref(name)} is in none of {files}{hint}")
    return out


def lost_files_warnings(
    totals: dict[str, tuple[MocapMap, int]], skipped: Sequence[dict[str, str]]
) -> list[str]:
    """Per map (``totals``: source -> (map, selected files)), how many files were skipped
    and why (the ``kind`` of each ``skipped`` entry)."""
    kinds: dict[str, Counter[str]] = defaultdict(Counter)
    for item in skipped:
        kinds[item["file"].split(":", 1)[0]][item.get("kind", "other")] += 1
    out = []
    for source, (m, total) in sorted(totals.items()):
        if kinds[source]:
            why = ", ".join(f"{n} {kind}" for kind, n in kinds[source].most_common())
            lost = sum(kinds[source].values())
            out.append(f"map {m.path}: {lost} of its {total} files skipped ({why}); see 'skipped:'")
    return out


#: A clip losing more than this fraction of its 30-fps frames to the drop rule is named in
#: a warning (the full build of the five shipped sources drops no frame).
DROPPED_WARN: Final = 0.05


def stretched_bones(off: npt.NDArray[np.bool_], dropped: npt.NDArray[np.bool_]) -> dict[str, int]:
    """Of the ``dropped`` frames, how many each bone (named by its child joint) is off its
    length in (``off``: ``trainer.data.build.off_length``, the drop rule's own test); bones
    off in none left out."""
    counts = off[dropped].sum(axis=0)
    return {JOINT_NAMES[c]: int(n) for c, n in zip(BONE_CHILDREN, counts, strict=True) if n}


def dropped_frames_warnings(results: Sequence[ClipResult]) -> list[str]:
    """Each clip that lost more than :data:`DROPPED_WARN` of its frames to the drop rule,
    with the reasons and, for ``bone_length``, the bones off their length most often: a map
    joining two source joints whose distance changes (docs/data.md, drop rule) lost frames
    in the summary's counts alone."""
    out = []
    for r in sorted(results, key=lambda r: r.job.label):
        lost = sum(r.drops.values())
        if (
            r.error is not None
            or not r.resampled_frames
            or lost <= DROPPED_WARN * r.resampled_frames
        ):
            continue
        why = ", ".join(f"{n} {reason}" for reason, n in r.drops.items() if n)
        if r.stretched:
            top = sorted(r.stretched.items(), key=lambda kv: -kv[1])[:3]
            bones = ", ".join(f"{bone} in {n}" for bone, n in top)
            why += f"; bones off their median length: {bones}"
        out.append(
            f"{r.job.label}: {lost} of its {r.resampled_frames} frames dropped ({why}); "
            "see the drop rule in docs/data.md"
        )
    return out


# --------------------------------------------------------------------------- crossed limbs

#: The links of a limb whose two joints are both on one side (parent, child), left side:
#: a map crossing one limb's sides below the torso (``left_foot = "foot.R_end"``,
#: ``right_foot = "foot.L_end"``) joins a left parent to a right child there.
SIDE_LINKS: Final = tuple(
    (int(p), int(c))
    for p, c in zip(BONE_PARENTS, BONE_CHILDREN, strict=True)
    if JOINT_NAMES[p].startswith("left_") and JOINT_NAMES[c].startswith("left_")
)
#: A link is crossed when, on both sides, the bone as mapped changes its length this many
#: times more (relative spread over a file's frames) than the bone joining the parent to
#: the other side's child: a rigid bone keeps its length, so the crossed pairing is the
#: rigid one. The shipped sources' bones have ratios under 0.4, crossed feet and wrists of
#: ReActIdle over 190 (a studio audit, 2026-12-07).
CROSSED_RATIO: Final = 10.0
#: ... and the bone as mapped changes its length by at least this (relative spread).
CROSSED_SPREAD: Final = 0.002
#: Hips and shoulders whose left-right axes point apart (dot < 0) in more than this
#: fraction of a file's frames: one whole limb's (or both legs' / arms') sides crossed.
ACROSS_FRACTION: Final = 0.5


def _spread(lengths: npt.NDArray[np.float64]) -> float:
    return float(np.std(lengths) / max(float(np.median(lengths)), 1e-6))


def _length(a: npt.NDArray[np.float64], b: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    return np.asarray(np.linalg.norm(a - b, axis=1), dtype=np.float64)


def crossed_links(positions: npt.NDArray[np.floating]) -> list[tuple[int, float, float]]:
    """The left-side links (child joint index, the mapped bone's relative spread, the
    crossed pairing's) whose sides look crossed in these ``[n, 21, 3]`` poses of one file,
    and ``(-1, fraction, 0)`` when the hips' and shoulders' left-right axes point apart in
    most of them (a whole limb crossed)."""
    p = np.asarray(positions, dtype=np.float64)
    if len(p) < 2:
        return []
    out = []
    for parent, child in SIDE_LINKS:
        lp, lc, rp, rc = p[:, parent], p[:, child], p[:, MIRROR[parent]], p[:, MIRROR[child]]
        mapped = (_spread(_length(lc, lp)), _spread(_length(rc, rp)))
        crossed = (_spread(_length(rc, lp)), _spread(_length(lc, rp)))
        if all(
            m >= CROSSED_SPREAD and m > CROSSED_RATIO * max(c, 1e-4)
            for m, c in zip(mapped, crossed, strict=True)
        ):
            out.append((child, max(mapped), max(crossed)))
    j = JOINT_INDEX
    hips = p[:, j["left_hip"]] - p[:, j["right_hip"]]
    shoulders = p[:, j["left_shoulder"]] - p[:, j["right_shoulder"]]
    apart = float(((hips * shoulders).sum(axis=1) < 0).mean())
    if apart > ACROSS_FRACTION:
        out.append((-1, apart, 0.0))
    return out


def crossed_limb_errors(results: Sequence[ClipResult]) -> list[str]:
    """A map that crosses one limb's left and right joints (not the whole body's sides:
    ``swap_sides``, :func:`_problem`): one message per map and crossed link, naming the
    joints as the map writes them, the first file and how many files show it; [] if none.
    The build refuses such a map: the crossed bone's frames are dropped, the rest trained
    with feet 0.26 m long (a studio audit, 2026-12-07)."""
    found: dict[tuple[str, int], list[tuple[ClipResult, float, float]]] = defaultdict(list)
    for r in results:
        if r.error is None and r.positions is not None:
            for child, mapped, crossed in crossed_links(r.positions):
                found[(r.job.map.path, child)].append((r, mapped, crossed))
    out = []
    for (path, child), hits in sorted(found.items(), key=lambda kv: (kv[0][0], kv[0][1])):
        r, mapped, crossed = hits[0]
        joints = r.job.map.joints_for(r.job.relpath)
        more = f" (and {len(hits) - 1} more files)" if len(hits) > 1 else ""
        if child < 0:
            out.append(
                f"map {path}: the hips' and the shoulders' left-right axes point apart in "
                f"{mapped:.0%} of the frames of {r.job.label}{more}: one limb's left and right "
                "joints are crossed from its first joint on (left_hip/right_hip = "
                f"{str(joints[JOINT_INDEX['left_hip']])!r}/"
                f"{str(joints[JOINT_INDEX['right_hip']])!r}, left_shoulder/right_shoulder = "
                f"{str(joints[JOINT_INDEX['left_shoulder']])!r}/"
                f"{str(joints[JOINT_INDEX['right_shoulder']])!r}): swap that limb's sides"
            )
            continue
        left, right = JOINT_NAMES[child], JOINT_NAMES[MIRROR[child]]
        parent = JOINT_NAMES[dict((c, p) for p, c in SIDE_LINKS)[child]]
        out.append(
            f"map {path}: {left} = {str(joints[child])!r} and {right} = "
            f"{str(joints[MIRROR[child]])!r} look crossed: the bone {parent} -> {left} changes "
            f"its length (spread {mapped:.1%} over the kept frames of {r.job.label}{more}; "
            f"frames further off dropped), while {parent} -> {right} keeps its length "
            f"({crossed:.1%}): swap the two joints' "
            "source names (whole-body sides: `swap_sides`)"
        )
    return out


# --------------------------------------------------------------------------- plausible bodies

#: Plausible medians of a group of poses (canonical frame, metres): the thigh's length, the
#: head's height over the pelvis, the lowest joint's height and the pelvis's (the floor is
#: y = 0), the toes ahead of the ankles. Outside them a map's unit, up axis, root position or
#: sides are likely wrong (inches read as cm gave 11 cm thighs; +Z read as +Y, figures lying
#: down, the head 2 mm over the pelvis; root channels replacing an offset they displace,
#: figures sunk 0.72 m through the floor; sides swapped, toes 10 cm behind).
PLAUSIBLE: Final = {
    "thigh": (0.2, 0.7),
    "head": (0.2, 1.2),
    "floor": (-0.15, 0.2),
    "pelvis": (0.3, 1.4),
    "toes": (0.0, 0.4),
}


def _medians(p: npt.NDArray[np.float64]) -> dict[str, float]:
    j = JOINT_INDEX
    feet = [j["left_foot"], j["right_foot"]]
    ankles = [j["left_ankle"], j["right_ankle"]]
    return {
        "thigh": float(
            np.median(np.linalg.norm(p[:, j["left_knee"]] - p[:, j["left_hip"]], axis=1))
        ),
        "head": float(np.median(p[:, j["head"], 1] - p[:, j["pelvis"], 1])),
        "floor": float(np.median(p[:, :, 1].min(axis=1))),
        "pelvis": float(np.median(p[:, j["pelvis"], 1])),
        "toes": float(np.median(p[:, feet, 2] - p[:, ankles, 2])),
    }


def _outside(key: str, value: float) -> bool:
    lo, hi = PLAUSIBLE[key]
    return not lo <= value <= hi


def _problem(v: dict[str, float], toes_slack: float = 0.0) -> str | None:
    """The likeliest wrong key of a group's medians, or None: the unit first (a wrong scale
    upsets every other measure), then the up axis, the root position, the sides (the toes
    ``toes_slack`` m further behind the ankles allowed: :data:`TAKE_TOES_SLACK`)."""
    if _outside("thigh", v["thigh"]):
        return f"median thigh length {v['thigh']:.3f} m (plausible 0.2-0.7): is the `unit` right?"
    if _outside("head", v["head"]):
        return (
            f"median head height over the pelvis {v['head']:.3f} m (plausible 0.2-1.2): "
            "is the `up_axis` right?"
        )
    if _outside("floor", v["floor"]) or _outside("pelvis", v["pelvis"]):
        return (
            f"median lowest joint at y = {v['floor']:.3f} m and pelvis at {v['pelvis']:.3f} m "
            "(the floor is y = 0; plausible -0.15-0.2 and 0.3-1.4): is `root_position` right "
            '("add" when the root\'s position channels are a displacement from its OFFSET)?'
        )
    if v["toes"] < PLAUSIBLE["toes"][0] - toes_slack:
        return (
            f"median toes {-v['toes']:.3f} m behind the ankles (facing +Z): are left and "
            "right swapped (`swap_sides`)?"
        )
    if v["toes"] > PLAUSIBLE["toes"][1]:
        return (
            f"median toes {v['toes']:.3f} m ahead of the ankles (plausible up to 0.4): "
            "is the `unit` right?"
        )
    return None


#: Bone lengths a dataset trains on (metres, from inclusive, to exclusive): a map whose two
#: source joints coincide (ReActIdle's ``spine`` sits on ``pelvis``) gives a bone of length
#: 0, a wrong unit bones of metres, which the models' reference skeleton (the manifest:
#: every bone in (0, 2) m) cannot hold.
BONE_RANGE_M: Final = (0.001, 2.0)
BONE_RANGE_TEXT: Final = "1 mm - 2 m"


def bad_bones(lengths: npt.NDArray[np.float64]) -> list[str]:
    """The bones (``[20]`` lengths in ``BONES`` order) outside :data:`BONE_RANGE_M`, each
    as ``"spine1 (pelvis -> spine1) 0.0000 m"``."""
    low, high = BONE_RANGE_M
    return [
        f"{JOINT_NAMES[c]} ({JOINT_NAMES[p]} -> {JOINT_NAMES[c]}) {v:.4f} m"
        for c, p, v in zip(BONE_CHILDREN, BONE_PARENTS, lengths, strict=True)
        if not low <= v < high
    ]


#: A take's (one file's) median toes may sit this much (m) further behind its ankles than a
#: source's before its sides are blamed: the shipped data's short runs and dashes (70
#: frames) have theirs up to 1.5 cm behind; swapped sides put them about 9 cm behind.
TAKE_TOES_SLACK: Final = 0.05
#: Implausible takes of a source named one by one; more are counted in one line.
TAKES_NAMED: Final = 10
#: ``meta`` key of a built dataset: the file of each take the checks found implausible
#: (clip name -> ``"<source>:<path>"``), so that training names the file too.
TAKE_FILES: Final = "take_files"

#: Per source: the implausible takes of its actors found plausible, (clip, problem) each.
_Takes = list[tuple[int, str]]


def _clip_frames(ds: PoseDataset) -> list[npt.NDArray[np.intp]]:
    """Each clip's frame indices, in the clip table's order."""
    order = np.argsort(ds.clip, kind="stable")
    bounds = np.searchsorted(ds.clip[order], np.arange(ds.num_clips + 1))
    return [order[a:b] for a, b in pairwise(bounds.tolist())]


def _takes(ds: PoseDataset, clips: Iterable[int], frames: list[npt.NDArray[np.intp]]) -> _Takes:
    """The ``clips`` (one per file) whose own medians are implausible, each with its
    problem: one take in inches, or turned +Z up, among plausible ones moves no median of
    its source or actor (a studio audit, 2026-12-07: served bodies 4x too big)."""
    out = []
    for c in clips:
        if len(frames[c]):
            v = _medians(ds.positions[frames[c]].astype(np.float64))
            if (problem := _problem(v, TAKE_TOES_SLACK)) is not None:
                out.append((int(c), problem))
    return out


def _map_keys(
    ds: PoseDataset,
) -> Iterator[tuple[str, npt.NDArray[np.bool_], str | None, list[str], _Takes]]:
    """Per source: its frames, and the warnings that name a likely wrong map key (`unit`,
    `up_axis`, `root_position`, `swap_sides`): the source's own, else its actors' (one
    actor's [[override]] with a wrong unit), and the takes of its other actors (one file
    exported in another unit or up axis)."""
    source = ds.clip_source[ds.clip]
    actor = ds.clip_actor[ds.clip]
    frames: list[npt.NDArray[np.intp]] | None = None
    for s in sorted(set(ds.clip_source.tolist())):
        sel = source == s
        problem = _problem(_medians(ds.positions[sel][::10].astype(np.float64)))
        if problem is not None:
            yield s, sel, f"{s}: {problem}", [], []
            continue
        found, flagged = [], set()
        actors = sorted(set(actor[sel].tolist()))
        for a in actors if len(actors) > 1 else []:
            p = ds.positions[sel & (actor == a)][::10].astype(np.float64)
            if (problem := _problem(_medians(p))) is not None:
                found.append(f"{s}, actor {a!r}: {problem} (the map's, or an [[override]]'s)")
                flagged.add(a)
        frames = _clip_frames(ds) if frames is None else frames
        clips = np.flatnonzero((ds.clip_source == s) & ~np.isin(ds.clip_actor, list(flagged)))
        yield s, sel, None, found, _takes(ds, clips.tolist(), frames)


def _take_warnings(ds: PoseDataset, source: str, takes: _Takes) -> list[str]:
    """One warning per implausible take (up to :data:`TAKES_NAMED`, the rest in one),
    naming its file where the build recorded it (``meta[TAKE_FILES]``), else its clip."""
    files: dict[str, str] = ds.meta.get(TAKE_FILES, {})
    out = []
    for c, problem in takes[:TAKES_NAMED]:
        name = str(ds.clip_name[c])
        file = files.get(name)
        where = f"{file} (clip {name!r})" if file else f"{source}, clip {name!r}"
        glob = f"glob = {file.split(':', 1)[-1]!r}" if file else "glob matching its file"
        out.append(
            f"{where}: {problem} (this take alone of its source: re-export it like the "
            f"others, or set that key for its file with an [[override]] {glob})"
        )
    if len(takes) > TAKES_NAMED:
        rest = [repr(str(ds.clip_name[c])) for c, _ in takes[TAKES_NAMED:]]
        out.append(
            f"{source}: {len(rest)} more takes implausible likewise: "
            f"{', '.join(rest[:EXAMPLES])}{', ...' if len(rest) > EXAMPLES else ''}"
        )
    return out


def implausible_takes(ds: PoseDataset) -> list[int]:
    """The clips (takes) :func:`implausible` names one by one (the build records their
    files: ``meta[TAKE_FILES]``)."""
    return [c for _, _, _, _, takes in _map_keys(ds) for c, _ in takes]


def implausible(ds: PoseDataset) -> list[str]:
    """The warnings of :func:`sanity_warnings` that name a likely wrong map key, per source,
    else per actor, and per take: what training refuses unless told to accept it (a studio
    audit, D4: a cm-for-metres map trained and served 3-m bodies, exit 0; 2026-12-07: one
    take in inches among 16, served bodies 4x too big)."""
    out = []
    for s, _, own, found, takes in _map_keys(ds):
        out += [own] if own else [*found, *_take_warnings(ds, s, takes)]
    return out


def sanity_warnings(ds: PoseDataset) -> list[str]:
    """What poses say of their map, where implausible (one warning per source, naming the
    likeliest wrong key; else one per actor, e.g. an [[override]] with a wrong unit, and one
    per take, e.g. one file exported in inches); the train split's mean bone lengths,
    which training refuses outside :data:`BONE_RANGE_M`; and a split the training needs
    (train, val) without frames."""
    out, said = [], False  # said: a finding that explains bones far off (training's test)
    for s, sel, own, found, takes in _map_keys(ds):
        if own is not None:  # the source's own: its bones say no more
            out.append(own)
            said = True
            continue
        lengths = np.median(bone_lengths(ds.positions[sel][::10].astype(np.float64)), axis=0)
        if bad := bad_bones(lengths):
            said = True
            out.append(
                f"{s}: median bone length outside {BONE_RANGE_TEXT}: {', '.join(bad)}: the "
                "map's two source joints of such a bone coincide (or lie far apart); map one "
                "of them to another joint (training refuses such a bone)"
            )
        out.extend(found)
        out.extend(_take_warnings(ds, s, takes))
        said = said or bool(found or takes)
    train = ds.split_mask("train")
    if train.any() and not said:  # (training's own test: the mean, which a take far off moves)
        mean = bone_lengths(ds.positions[train]).mean(axis=0, dtype=np.float64)
        if bad := bad_bones(mean):
            out.append(
                f"the train split's mean bone length is outside {BONE_RANGE_TEXT} for "
                f"{', '.join(bad)}: training refuses this dataset (a few frames far off "
                "their size move the mean)"
            )
    for split in ("train", "val", "test"):
        if not (ds.clip_split == split).any():
            out.append(f"no {split} clips: training refuses this dataset (docs/data.md, splits)")
    return out
