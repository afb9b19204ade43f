"""``pose-trainer dataset``: mocap archives -> one canonical pose file (``data/poses.npz``).

Pipeline, per clip (in worker processes):

1. read the clip (BVH: :mod:`core.bvh`; Acclaim ASF/AMC: :mod:`trainer.data.asf`, the AMC
   paired with its subject's ASF by the map); the joint map picks the 21 source joints (or
   points part-way between two of them);
2. resample to 30 fps: keep every k-th frame when the source rate is an integer multiple
   ``k`` of 30 (done *before* forward kinematics, so it is exact and cheap), otherwise
   linear interpolation of the joint positions at ``t = n / 30``;
3. scale to metres, turn the source's up axis to +Y;
4. drop broken frames (first matching reason counts): ``non_finite`` (any NaN/inf),
   ``teleport`` (pelvis moved more than 1 m since the previous 30-fps frame),
   ``bone_length`` (any bone deviates from the clip's median length of that bone by more
   than 5 % + 1 mm);
5. canonicalise every pose with :func:`core.geometry.canonicalise`.

Each map's data is found, checked and extracted first (:mod:`trainer.data.sources`).
Then clips are split by clip (:mod:`trainer.data.splits`): the clips a map holds out go to
``holdout``, the others to train/val/test (stratified by source, content and actor, seeded);
everything is written atomically by :func:`trainer.data.dataset.save_dataset`. What the
build tells of its maps (a source not found or whose globs select nothing, a joint name in
none of a map's files, unused globs, no licence, implausible bodies) is
:mod:`trainer.data.checks`; the printed summary :mod:`trainer.data.summary`.
"""

from __future__ import annotations

import multiprocessing
import os
import shutil
import tempfile
import time
from collections import Counter, defaultdict
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.bvh import BVH, BVHError, read_bvh
from core.geometry import canonical_transform, transform_yaw
from core.skeleton import BONE_CHILDREN, JOINT_NAMES, bone_lengths
from core.text import close_match
from trainer.data.asf import AMC, ASFError, read_amc, read_asf
from trainer.data.checks import (
    TAKE_FILES,
    amc_rate_warning,
    case_warnings,
    crossed_limb_errors,
    dropped_frames_warnings,
    implausible_takes,
    licence_warning,
    lost_files_warnings,
    missing_joint_errors,
    stretched_bones,
    unused_glob_warnings,
)
from trainer.data.checks import sanity_warnings as sanity_warnings
from trainer.data.dataset import (
    FORMAT_VERSION,
    FPS,
    PoseDataset,
    is_dataset_file,
    save_dataset,
)
from trainer.data.maps import (
    MapError,
    MocapMap,
    joint_positions,
    load_maps,
)
from trainer.data.sources import BuildError as BuildError  # (its callers' name too)
from trainer.data.sources import Located, SourceInput, locate_sources, pair_skeleton
from trainer.data.splits import SPLIT_FRACTIONS, assign_splits

#: Drop-rule thresholds.
BONE_TOLERANCE = 0.05  # relative deviation from the clip's median bone length
BONE_TOLERANCE_ABS = 0.001  # metres, added to the relative tolerance (short bones)
TELEPORT_METRES = 1.0  # pelvis displacement between consecutive 30-fps frames
DROP_REASONS: tuple[str, ...] = ("non_finite", "teleport", "bone_length")
RESAMPLING = (
    "integer ratio k = source_fps / 30: keep frames 0, k, 2k, ... (before FK); "
    "otherwise linear interpolation of joint positions at t = n / 30"
)
#: Names of the bones (by child joint) in the order of ``core.skeleton.BONES``.
BONE_NAMES: tuple[str, ...] = tuple(JOINT_NAMES[c] for c in BONE_CHILDREN)


# --------------------------------------------------------------------------- per clip


@dataclass(frozen=True)
class ClipJob:
    path: str  # absolute file path
    relpath: str  # path relative to the source root, '/'-separated (for maps and messages)
    label: str  # "<source>:<relpath>", used in messages
    map: MocapMap
    skeleton: str | None = None  # absolute path of the ASF of an AMC clip (reader "asf")


@dataclass
class ClipResult:
    job: ClipJob
    positions: npt.NDArray[np.float32] | None = None  # [n, 21, 3] canonical metres
    yaw: npt.NDArray[np.float32] | None = None  # [n] canonical transform: facing angle
    root: npt.NDArray[np.float32] | None = None  # [n, 3] canonical transform: translation
    frames: npt.NDArray[np.int32] | None = None  # [n] frame index at 30 fps
    source_frames: int = 0
    source_fps: float = 0.0
    resampled_frames: int = 0
    drops: dict[str, int] = field(default_factory=dict)
    stretched: dict[str, int] = field(default_factory=dict)  # bone -> frames it dropped
    bone_sum: npt.NDArray[np.float64] | None = None  # sum over kept frames, per bone
    error: str | None = None
    kind: str = ""  # why the file was skipped (a few words), with ``error``
    checked: bool = False  # the file was read and its joint names compared with the map's
    missing: dict[str, str] = field(default_factory=dict)  # map's names not in it -> close one


class MissingJoints(MapError):
    """Source joints a map names that a file lacks (each with a close name of the file's,
    or '')."""

    def __init__(self, message: str, missing: dict[str, str]) -> None:
        super().__init__(message)
        self.missing = missing

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its arguments (the default passes the message alone: unpickling it
        in the dataset builder's pool was a TypeError)."""
        return type(self), (self.args[0], self.missing), self.__dict__


def _clean_fps(fps: float) -> float:
    """Snap header rates like 30.00003 (Frame Time 0.0333333) to the nearest integer."""
    nearest = round(fps)
    return float(nearest) if nearest > 0 and abs(fps - nearest) < 0.01 * fps else fps


def resample_indices(n_frames: int, fps: float, target: int = FPS) -> tuple[int, int]:
    """``(k, n_out)`` if the rate is an integer multiple k of ``target``, else ``(0, n_out)``."""
    ratio = fps / target
    k = round(ratio)
    if k >= 1 and abs(ratio - k) < 1e-6:
        return k, (n_frames + k - 1) // k if n_frames else 0
    n_out = int(np.floor((n_frames - 1) * target / fps + 1e-9)) + 1 if n_frames else 0
    return 0, n_out


def interpolate_positions(
    positions: npt.NDArray[np.float64], fps: float, target: int = FPS
) -> npt.NDArray[np.float64]:
    """Linear interpolation of ``[F, J, 3]`` positions at ``t = n / target``."""
    n_frames = positions.shape[0]
    _, n_out = resample_indices(n_frames, fps, target)
    s = np.arange(n_out, dtype=np.float64) * (fps / target)
    i0 = np.clip(np.floor(s).astype(np.intp), 0, max(n_frames - 1, 0))
    i1 = np.minimum(i0 + 1, n_frames - 1)
    w = (s - i0)[:, None, None]
    return np.asarray(positions[i0] * (1.0 - w) + positions[i1] * w)


def off_length(world: npt.NDArray[np.float64]) -> npt.NDArray[np.bool_]:
    """``[F, 20]``: each bone of ``[F, 21, 3]`` world metres off its clip's median length
    (over the finite frames) by more than the drop rule allows; none where no frame is
    finite."""
    lengths = bone_lengths(world)  # [F, 20]
    finite = np.isfinite(world).all(axis=(1, 2))
    if not finite.any():
        return np.zeros(lengths.shape, dtype=np.bool_)
    median = np.median(lengths[finite], axis=0)
    with np.errstate(invalid="ignore"):
        return np.abs(lengths - median) > BONE_TOLERANCE * median + BONE_TOLERANCE_ABS  # type: ignore[no-any-return]


def drop_reasons(
    world: npt.NDArray[np.float64], off: npt.NDArray[np.bool_] | None = None
) -> npt.NDArray[np.int8]:
    """Per-frame drop code for ``[F, 21, 3]`` world metres at 30 fps (``off``: its
    :func:`off_length`, if known): 0 = keep, otherwise ``1 + DROP_REASONS.index(reason)``
    for the first matching reason."""
    n = world.shape[0]
    code = np.zeros(n, dtype=np.int8)
    finite = np.isfinite(world).all(axis=(1, 2))
    code[~finite] = 1
    pelvis = world[:, JOINT_NAMES.index("pelvis")]
    with np.errstate(invalid="ignore"):
        step = np.linalg.norm(np.diff(pelvis, axis=0), axis=-1)
        teleport = np.zeros(n, dtype=bool)
        teleport[1:] = step > TELEPORT_METRES
    code[(code == 0) & teleport] = 2
    bad = (off_length(world) if off is None else off).any(axis=1)
    code[(code == 0) & bad] = 3
    return code


def read_clip(job: ClipJob) -> tuple[BVH | AMC, float | None]:
    """Parse one clip: ``(clip, metres per unit of its ASF skeleton or None)``."""
    if job.map.reader != "asf":
        return read_bvh(job.path, name=job.label), None
    if job.skeleton is None:
        raise MapError(f"{job.label}: no ASF skeleton paired with this AMC")
    skeleton = read_asf(job.skeleton)
    return read_amc(job.path, skeleton, name=job.label), skeleton.metres_per_unit


def check_joints(job: ClipJob, clip: BVH | AMC) -> None:
    """``MissingJoints`` if the file lacks source joints the map names for it."""
    names = {n for j in job.map.joints_for(job.relpath) for n in j.names}
    missing = sorted(names - set(clip.joint_names))
    if missing:
        raise MissingJoints(
            f"{job.label}: joints {missing} of map {job.map.path} not in the file",
            {n: close_match(n, clip.joint_names) or "" for n in missing},
        )


def read_world(job: ClipJob) -> tuple[npt.NDArray[np.float64], int, float, int]:
    """Read one clip and give its 21 canonical joints at 30 fps in world metres, +Y up:
    ``(world [n_out, 21, 3], source frames, source fps, n_out)``. Raises ``BVHError`` /
    ``ASFError`` / ``MapError`` for unreadable files and maps that do not fit them."""
    clip, scale_hint = read_clip(job)
    check_joints(job, clip)
    return clip_world(job, clip, scale_hint)


def clip_world(
    job: ClipJob, clip: BVH | AMC, scale_hint: float | None
) -> tuple[npt.NDArray[np.float64], int, float, int]:
    """:func:`read_world` of a parsed clip whose joints the map's names are in."""
    joints = job.map.joints_for(job.relpath)
    fps = _clean_fps(job.map.fps_for(job.relpath, clip.fps))
    k, n_out = resample_indices(clip.num_frames, fps)
    if k:
        world = joint_positions(clip, joints, frames=slice(None, None, k))
    else:
        world = interpolate_positions(joint_positions(clip, joints), fps)
    if job.map.root_position == "add" and isinstance(clip, BVH):
        # The root's position channels are a displacement from its OFFSET: add the OFFSET
        # on the axes they replaced (the whole figure moves with the root).
        root = clip.joints[0]
        for ch in root.channels:
            axis = "xyz".find(ch[0].lower()) if ch.lower().endswith("position") else -1
            if axis >= 0:
                world[..., axis] += root.offset[axis]
    scale = job.map.scale_for(job.relpath, scale_hint)
    world = np.einsum("ij,fkj->fki", job.map.up_matrix_for(job.relpath), world * scale)
    return world, clip.num_frames, fps, n_out


def process_clip(job: ClipJob) -> ClipResult:
    """Read, resample, convert, filter and canonicalise one clip (runs in a worker)."""
    result = ClipResult(job=job)
    try:
        clip, scale_hint = read_clip(job)
        result.checked = True
        check_joints(job, clip)
        world, result.source_frames, result.source_fps, n_out = clip_world(job, clip, scale_hint)
        result.resampled_frames = n_out
        off = off_length(world)
        code = drop_reasons(world, off)
        result.drops = {r: int((code == i + 1).sum()) for i, r in enumerate(DROP_REASONS)}
        result.stretched = stretched_bones(off, code == 3)
        keep = code == 0
        frame = canonical_transform(world[keep])
        canon = frame.to_canonical(world[keep])
        result.positions = canon.astype(np.float32)
        result.yaw = transform_yaw(frame).astype(np.float32)
        result.root = frame.translation.astype(np.float32)
        result.frames = np.flatnonzero(keep).astype(np.int32)
        result.bone_sum = bone_lengths(canon).sum(axis=0)
    except MissingJoints as exc:
        result.error, result.kind, result.missing = str(exc), "lacking joints", exc.missing
    except (BVHError, ASFError) as exc:
        result.error, result.kind = str(exc), "unreadable"
    except MapError as exc:
        result.error, result.kind = str(exc), "not fitting the map"
    except Exception as exc:  # one bad file must not stop the build
        result.error, result.kind = f"{job.label}: {type(exc).__name__}: {exc}", "failed"
    return result


# --------------------------------------------------------------------------- build


@dataclass
class BuildReport:
    """What the build did (also stored, in JSON form, as the dataset's ``meta``)."""

    meta: dict[str, Any]
    dataset: PoseDataset
    out: Path


@contextmanager
def _progress(enabled: bool) -> Iterator[Any]:
    if not enabled:
        yield None
        return
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        SpinnerColumn,
        TextColumn,
        TimeElapsedColumn,
    )

    with Progress(
        SpinnerColumn(),
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        transient=False,
        console=Console(stderr=True),  # stdout: the summary only
    ) as progress:
        yield progress


def _iter_results(jobs: list[ClipJob], workers: int) -> Iterator[ClipResult]:
    if workers <= 1:
        for job in jobs:
            yield process_clip(job)
        return
    # forkserver: workers start from a clean process, safe even when the caller has already
    # started threads (e.g. torch's thread pools in a test session).
    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    ctx = multiprocessing.get_context(method)
    with ctx.Pool(workers) as pool:
        yield from pool.imap_unordered(process_clip, jobs, chunksize=4)


def _escape(text: str) -> str:
    """``text`` printed as it is by rich (map keys like ``[joints]`` are not markup)."""
    from rich.markup import escape

    return escape(text)


def _skip(skipped: list[dict[str, str]], say: Any, label: str, reason: str, kind: str) -> None:
    """Record a skipped file (its ``kind``: why, in a few words, for the per-map count)."""
    skipped.append({"file": label, "reason": reason, "kind": kind})
    text = reason if reason.startswith(label) else f"{label}: {reason}"
    say(f"[yellow]skipped {_escape(text)}")


def _jobs_of(src: SourceInput, skipped: list[dict[str, str]], say: Any) -> list[ClipJob]:
    """A job per file the map selects (an AMC with its ASF, or skipped without one)."""
    jobs = []
    for rel in src.selected:
        label = f"{src.map.source}:{rel}"
        skeleton = None
        if src.map.reader == "asf":
            try:
                skeleton = str(src.root / pair_skeleton(src.map, rel, src.files))
            except MapError as exc:
                _skip(skipped, say, label, str(exc), "without one ASF skeleton")
                continue
        jobs.append(ClipJob(str(src.root / rel), rel, label, src.map, skeleton))
    return jobs


def _source_warnings(located: Located) -> list[str]:
    """Build-time warnings of the sources: not found, unused globs, no licence, AMC files
    read at CMU's rate for want of one."""
    out = [f"not built: {m}" for m in located.missing] + located.shadowed
    for src in located.sources:
        out += unused_glob_warnings(src.map, src.selected) + case_warnings(src.map, src.files)
        for w in (licence_warning(src.map), amc_rate_warning(src.map, src.selected)):
            if w is not None:
                out.append(w)
    return out


def build_dataset(
    mocap_dir: str | Path,
    out: str | Path,
    *,
    maps_dir: str | Path | None = None,
    seed: int = 0,
    workers: int = 2,
    progress: bool = True,
    log: Any = None,
) -> BuildReport:
    """Build the dataset from every source a map describes and write it to ``out``."""
    t0 = time.perf_counter()
    mocap_dir = Path(mocap_dir)
    if not mocap_dir.is_dir():
        raise BuildError(f"{mocap_dir}: mocap folder not found")
    if (problem := out_problem(Path(out), mocap_dir)) is not None:
        raise BuildError(f"--out {problem}")
    required = maps_dir is not None  # --maps: the user's own sources, each one needed
    maps_dir = Path(maps_dir) if maps_dir is not None else Path(__file__).parent.parent / "maps"
    maps = load_maps(maps_dir)
    say = log if log is not None else (lambda _msg: None)

    with ExitStack() as stack, _progress(progress) as bar:
        workdir = Path(tempfile.mkdtemp(prefix="marionette-mocap-"))
        stack.callback(shutil.rmtree, workdir, True)
        task = bar.add_task("finding sources", total=None) if bar else None
        located = locate_sources(mocap_dir, maps, workdir, log=say, required=required)
        if bar is not None and task is not None:
            bar.update(task, total=1, completed=1)
        if located.unmatched:
            raise BuildError("\n".join(located.unmatched))
        sources = located.sources
        if not sources:
            raise BuildError(
                "\n".join(
                    [f"{mocap_dir}: no mocap found for any map in {maps_dir}", *located.missing]
                )
            )
        warnings = _source_warnings(located)  # printed with the summary, kept in meta

        skipped: list[dict[str, str]] = []
        jobs = [job for src in sources for job in _jobs_of(src, skipped, say)]
        totals = {src.map.source: (src.map, len(src.selected)) for src in sources}
        # Largest files first: better load balance across workers.
        jobs.sort(key=lambda j: -os.path.getsize(j.path))
        infos = {}
        missed: dict[str, list[str]] = defaultdict(list)  # per source, why each file missed
        for job in list(jobs):
            try:
                infos[job.path] = job.map.clip_info(job.relpath)
            except MapError as exc:
                _skip(skipped, say, job.label, str(exc), "not matched by [metadata] pattern")
                missed[job.map.source].append(str(exc))
                jobs.remove(job)
        for source, (m, total) in totals.items():  # a pattern no file matches is a typo
            if total and len(missed[source]) == total:  # (the source went without a word)
                raise MapError(
                    f"map {m.path}: its [metadata] pattern matches none of its {total} files; "
                    f"the first: {missed[source][0]}"
                )
        names = Counter(i.name for i in infos.values())
        dupes = sorted(n for n, c in names.items() if c > 1)
        if dupes:
            raise BuildError(
                f"clip names are not unique: {dupes[:5]} (fix the map's name template)"
            )

        read: list[ClipResult] = []
        held: list[str] = []  # files lacking a joint: said once no name is a typo
        task = bar.add_task("reading clips", total=len(jobs)) if bar else None
        for res in _iter_results(jobs, workers):
            read.append(res)
            if res.error is not None:
                _skip(skipped, held.append if res.missing else say, res.job.label, res.error,
                      res.kind)  # fmt: skip
            elif res.positions is None or len(res.positions) == 0:
                reason = "no frames left after resampling and the drop rule"
                _skip(skipped, say, res.job.label, reason, "without frames")
            if bar is not None and task is not None:
                bar.advance(task)
        fatal = missing_joint_errors(read)
        if fatal:  # (each file's own line came first: one per file, a misspelt name's ten)
            raise MapError("\n".join(fatal))
        for line in held:
            say(line)
    warnings += lost_files_warnings(totals, skipped) + dropped_frames_warnings(read)

    # Deterministic order: by clip name, whatever order the workers finished in.
    results = sorted((r for r in read if r.error is None), key=lambda r: infos[r.job.path].name)
    kept = [r for r in results if r.positions is not None and len(r.positions)]
    if not kept:
        raise BuildError(f"no frames survived: {len(skipped)} files skipped (listed above)")
    if crossed := crossed_limb_errors(kept):  # (one limb's sides: trained bones 0.26 m feet)
        raise MapError("\n".join(crossed))
    clip_infos = [infos[r.job.path] for r in kept]
    positions = np.concatenate([r.positions for r in kept if r.positions is not None])
    frames = np.concatenate([r.frames for r in kept if r.frames is not None])
    yaw = np.concatenate([r.yaw for r in kept if r.yaw is not None])
    root = np.concatenate([r.root for r in kept if r.root is not None])
    clip = np.concatenate(
        [
            np.full(len(r.positions), i, dtype=np.int32)
            for i, r in enumerate(kept)
            if r.positions is not None
        ]
    )
    clip_name = np.array([c.name for c in clip_infos], dtype=str)
    clip_source = np.array([c.source for c in clip_infos], dtype=str)
    clip_content = np.array([c.content for c in clip_infos], dtype=str)
    clip_actor = np.array([c.actor for c in clip_infos], dtype=str)
    split = assign_splits(
        clip_name.tolist(),
        clip_source.tolist(),
        clip_content.tolist(),
        seed,
        actors=clip_actor.tolist(),
        fixed=[r.job.map.split_for(r.job.relpath) for r in kept],
    )

    drops: dict[str, int] = dict.fromkeys(DROP_REASONS, 0)
    drops_by_source: dict[str, dict[str, int]] = {}
    for r in results:
        per = drops_by_source.setdefault(r.job.map.source, dict.fromkeys(DROP_REASONS, 0))
        for reason, count in r.drops.items():
            drops[reason] += count
            per[reason] += count
    bone_means: dict[str, dict[str, float]] = {}
    for source in sorted(set(clip_source.tolist())):
        sel = [r for r in kept if r.job.map.source == source and r.bone_sum is not None]
        total = np.sum([r.bone_sum for r in sel if r.bone_sum is not None], axis=0)
        count = sum(len(r.positions) for r in sel if r.positions is not None)
        bone_means[source] = {
            b: round(float(v), 4) for b, v in zip(BONE_NAMES, total / count, strict=True)
        }
    # Per body: (source, actor) -> mean canonical bone lengths (the held-out bodies' spread).
    bone_means_by_actor: dict[str, dict[str, dict[str, float]]] = {}
    for (source, actor), sel in _group_by_actor(kept, infos).items():
        total = np.sum([r.bone_sum for r in sel if r.bone_sum is not None], axis=0)
        count = sum(len(r.positions) for r in sel if r.positions is not None)
        bone_means_by_actor.setdefault(source, {})[actor] = {
            b: round(float(v), 4) for b, v in zip(BONE_NAMES, total / count, strict=True)
        }

    meta: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "fps": FPS,
        "seed": seed,
        "split_fractions": SPLIT_FRACTIONS,
        "split_rule": "by clip; clips a map holds out -> holdout, clips a map's override "
        "puts in a split -> that split; the others stratified by (source, content, actor); "
        "per stratum of n clips: "
        "n=1 -> test, n=2 -> test+train, else max(1, round(n*f)) test and val",
        "holdout": {s.map.source: list(s.map.holdout) for s in sources if s.map.holdout},
        "units": "metres",
        "frame": "canonical: pelvis floor projection at the origin, facing +Z, left +X, +Y up",
        "joints": list(JOINT_NAMES),
        "archives": [dict(s.origin, source=s.map.source) for s in sources],
        "maps": [
            {"source": s.map.source, "file": map_name(s.map.path), "sha256": s.map.sha256}
            for s in sources
        ],
        "licences": {s.map.source: s.map.licence for s in sources},
        "resampling": RESAMPLING,
        "drop_rule": {
            "non_finite": "any NaN/inf coordinate",
            "teleport_m": TELEPORT_METRES,
            "bone_tolerance_rel": BONE_TOLERANCE,
            "bone_tolerance_abs_m": BONE_TOLERANCE_ABS,
        },
        "dropped_frames": drops,
        "dropped_frames_by_source": drops_by_source,
        "skipped_files": skipped,
        "warnings": warnings,
        "source_frames": {
            s.map.source: sum(r.source_frames for r in results if r.job.map.source == s.map.source)
            for s in sources
        },
        "resampled_frames": {
            s.map.source: sum(
                r.resampled_frames for r in results if r.job.map.source == s.map.source
            )
            for s in sources
        },
        "mean_bone_lengths_m": bone_means,
        "mean_bone_lengths_m_by_actor": bone_means_by_actor,
        "num_clips": len(kept),
        "num_frames": len(positions),
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    dataset = PoseDataset(
        positions=positions.astype(np.float32),
        yaw=yaw.astype(np.float32),
        root=root.astype(np.float32),
        clip=clip.astype(np.int32),
        frame=frames.astype(np.int32),
        clip_name=clip_name,
        clip_source=clip_source,
        clip_content=clip_content,
        clip_style=np.array([c.style for c in clip_infos], dtype=str),
        clip_actor=clip_actor,
        clip_split=split.astype(str),
        meta=meta,
    )
    # what the poses say of their maps (a wrong unit, up axis, sides; a split without
    # frames): kept with the others, so the dataset, the manifest and training say it too;
    # the files of the takes found implausible alone, so that each is named by its file
    if takes := implausible_takes(dataset):
        meta[TAKE_FILES] = {clip_infos[c].name: kept[c].job.label for c in takes}
    meta["warnings"] = [*warnings, *sanity_warnings(dataset)]
    meta["build_seconds"] = round(time.perf_counter() - t0, 1)
    out = save_dataset(out, dataset)
    return BuildReport(meta=meta, dataset=dataset, out=out)


def out_problem(out: Path, mocap_dir: Path) -> str | None:
    """Why ``out`` may not be written by a build reading ``mocap_dir``, or None: a file
    there that is not a dataset this tool wrote (a studio audit, 2026-12-07: a
    ``manifest.json`` became a zip without a word), or a path inside the mocap folder (the
    build reads it: the dataset written there changed that folder's digest next build).
    A dataset file there is rebuilt (overwritten), as ``make dataset`` does."""
    if (out.exists() or out.is_symlink()) and not is_dataset_file(out):
        return (
            f"{out}: exists and is not a dataset file `pose-trainer dataset` wrote (not "
            "overwritten): give another --out, or move that file away first"
        )
    try:
        out.resolve().relative_to(mocap_dir.resolve())
    except ValueError:
        return None
    return (
        f"{out}: is inside the mocap folder {mocap_dir} (the build reads it: a dataset "
        "written there changes that folder's sources): write it elsewhere, e.g. data/"
    )


def _group_by_actor(
    kept: Sequence[ClipResult], infos: dict[str, Any]
) -> dict[tuple[str, str], list[ClipResult]]:
    groups: dict[tuple[str, str], list[ClipResult]] = defaultdict(list)
    for r in kept:
        groups[(r.job.map.source, infos[r.job.path].actor)].append(r)
    return dict(sorted(groups.items()))


#: The shipped maps' folder, as the provenance names it (``trainer/maps/<file>``).
SHIPPED_MAPS = Path(__file__).resolve().parent.parent / "maps"


def map_name(path: str) -> str:
    """How the dataset (and the models' provenance) names a map file: a shipped map by its
    place in the repository (``trainer/maps/reactidle.toml``), any other by its file name
    (``studio.toml``; with its sha256 beside it), never a local path (a studio's
    ``/home/<user>/maps/studio.toml`` was recorded, a studio audit, 2026-12-07)."""
    resolved = Path(path).resolve()
    if resolved.parent == SHIPPED_MAPS:
        return f"trainer/maps/{resolved.name}"
    return resolved.name


# --------------------------------------------------------------------------- summary


def print_summary(report: BuildReport, console: Any = None) -> None:
    """Print the build's tables, skipped files and warnings (:mod:`trainer.data.summary`)."""
    from trainer.data.summary import print_summary as print_tables

    print_tables(report, console)
