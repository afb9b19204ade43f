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

Then clips are split by clip: the clips a map holds out go to ``holdout``, the others to
train/val/test (stratified by source, content and actor, seeded); everything is written
atomically by :func:`trainer.data.dataset.save_dataset`.
"""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import shutil
import subprocess
import tarfile
import tempfile
import time
import zlib
from collections import Counter, defaultdict
from collections.abc import Iterator, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt

from core.bvh import BVH, BVHError, read_bvh
from core.geometry import canonical_transform, transform_yaw
from core.io import sha256_file
from core.skeleton import BONE_CHILDREN, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, bone_lengths
from trainer.data.asf import AMC, ASFError, read_amc, read_asf
from trainer.data.dataset import FORMAT_VERSION, FPS, SPLITS, PoseDataset, save_dataset
from trainer.data.maps import MapError, MocapMap, glob_to_regex, joint_positions, load_maps

#: Default split fractions (train, val, test).
SPLIT_FRACTIONS: dict[str, float] = {"train": 0.90, "val": 0.05, "test": 0.05}
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


class BuildError(RuntimeError):
    """The dataset cannot be built (no data, checksum mismatch, bad maps...)."""


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
    bone_sum: npt.NDArray[np.float64] | None = None  # sum over kept frames, per bone
    error: str | None = None


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


def drop_reasons(world: npt.NDArray[np.float64]) -> npt.NDArray[np.int8]:
    """Per-frame drop code for ``[F, 21, 3]`` world metres at 30 fps.

    0 = keep, otherwise ``1 + DROP_REASONS.index(reason)`` for the first matching reason.
    """
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
    lengths = bone_lengths(world)  # [F, 20]
    if finite.any():
        median = np.median(lengths[finite], axis=0)
        with np.errstate(invalid="ignore"):
            bad = (np.abs(lengths - median) > BONE_TOLERANCE * median + BONE_TOLERANCE_ABS).any(
                axis=1
            )
        code[(code == 0) & bad] = 3
    return code


def read_world(job: ClipJob) -> tuple[npt.NDArray[np.float64], int, float, int]:
    """Read one clip and give its 21 canonical joints at 30 fps in world metres, +Y up:
    ``(world [n_out, 21, 3], source frames, source fps, n_out)``. Raises ``BVHError`` /
    ``ASFError`` / ``MapError`` for unreadable files and maps that do not fit them."""
    clip: BVH | AMC
    scale_hint: float | None = None
    if job.map.reader == "asf":
        if job.skeleton is None:
            raise MapError(f"{job.label}: no ASF skeleton paired with this AMC")
        skeleton = read_asf(job.skeleton)
        clip = read_amc(job.path, skeleton, name=job.label)
        scale_hint = skeleton.metres_per_unit
    else:
        clip = read_bvh(job.path, name=job.label)
    joints = job.map.joints_for(job.relpath)
    missing = sorted({n for j in joints for n in j.names} - set(clip.joint_names))
    if missing:
        raise MapError(f"{job.label}: joints {missing} of map {job.map.path} not in the file")
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
        world, result.source_frames, result.source_fps, n_out = read_world(job)
        result.resampled_frames = n_out
        code = drop_reasons(world)
        result.drops = {r: int((code == i + 1).sum()) for i, r in enumerate(DROP_REASONS)}
        keep = code == 0
        frame = canonical_transform(world[keep])
        canon = frame.to_canonical(world[keep])
        result.positions = canon.astype(np.float32)
        result.yaw = transform_yaw(frame).astype(np.float32)
        result.root = frame.translation.astype(np.float32)
        result.frames = np.flatnonzero(keep).astype(np.int32)
        result.bone_sum = bone_lengths(canon).sum(axis=0)
    except (BVHError, ASFError, MapError) as exc:
        result.error = str(exc)
    except Exception as exc:  # one bad file must not stop the build
        result.error = f"{job.label}: {type(exc).__name__}: {exc}"
    return result


# --------------------------------------------------------------------------- sources


@dataclass
class SourceInput:
    map: MocapMap
    root: Path
    origin: dict[str, Any]  # provenance: archive (+sha256) or folder


def read_checksums(mocap_dir: Path) -> dict[str, str]:
    """``SHA256SUMS`` of the mocap folder as ``{file name: hex digest}`` (empty if absent)."""
    sums: dict[str, str] = {}
    path = mocap_dir / "SHA256SUMS"
    if path.is_file():
        for line in path.read_text().splitlines():
            parts = line.split()
            if len(parts) == 2:
                sums[parts[1].lstrip("*")] = parts[0].lower()
    return sums


def _all_files(root: Path) -> list[str]:
    """Every file under ``root``, as sorted '/'-separated relative paths."""
    out: list[str] = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames.sort()
        rel_dir = Path(dirpath).relative_to(root).as_posix()
        for name in sorted(filenames):
            out.append(name if rel_dir == "." else f"{rel_dir}/{name}")
    return out


def _selected_files(root: Path, mocap_map: MocapMap) -> list[str]:
    return [rel for rel in _all_files(root) if mocap_map.selects(rel)]


def folder_digest(root: Path, files: Sequence[str]) -> str:
    """A folder source's content, hashed: the sha256 of its files' lines ``<sha256>  <relative
    path>`` (``sha256sum``'s form), sorted by path (a folder had no hash: the manifest
    named it with the sha256 "None")."""
    lines = "".join(f"{sha256_file(root / rel)}  {rel}\n" for rel in sorted(files))
    return hashlib.sha256(lines.encode()).hexdigest()


def pair_skeleton(mocap_map: MocapMap, relpath: str, files: Sequence[str]) -> str:
    """The one file of ``files`` (relative paths) matching the map's ``skeleton`` globs for
    a motion file; ``MapError`` naming the globs when none or several match."""
    patterns = mocap_map.skeleton_globs(relpath)
    regexes = [glob_to_regex(p) for p in patterns]
    found = [f for f in files if any(r.match(f) for r in regexes)]
    if len(found) != 1:
        what = "no file" if not found else f"{len(found)} files ({', '.join(found[:3])})"
        raise MapError(f"{mocap_map.path}: skeleton globs {patterns} match {what}")
    return found[0]


def _start_extract(archive: Path, dest: Path) -> subprocess.Popen[bytes] | None:
    dest.mkdir(parents=True, exist_ok=True)
    tar = shutil.which("tar")
    if tar is None:
        return None
    return subprocess.Popen(
        [tar, "-xf", str(archive), "-C", str(dest)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )


def locate_sources(
    mocap_dir: Path, maps: Sequence[MocapMap], workdir: Path, log: Any = None
) -> list[SourceInput]:
    """Find each map's data: ``<mocap>/<archive>`` (extracted into ``workdir``, all archives
    in parallel), else an extracted folder ``<mocap>/<archive stem>/`` or ``<mocap>/``."""
    checksums = read_checksums(mocap_dir)
    pending: list[tuple[MocapMap, Path, Path, subprocess.Popen[bytes] | None]] = []
    found: list[SourceInput] = []
    for m in maps:
        archive = mocap_dir / m.archive if m.archive else None
        if archive is not None and archive.is_file():
            dest = workdir / m.source
            pending.append((m, archive, dest, _start_extract(archive, dest)))
            continue
        candidates = []
        if m.archive_stem:
            candidates.append(mocap_dir / m.archive_stem)
        candidates.append(mocap_dir)
        for root in candidates:
            if root.is_dir() and (selected := _selected_files(root, m)):
                origin: dict[str, Any] = {
                    "kind": "folder", "path": str(root), "files": len(selected),
                    "files_sha256": folder_digest(root, selected),
                }  # fmt: skip
                if m.archive and m.archive in checksums:
                    # Not verifiable from a folder: the sum SHA256SUMS lists for its archive.
                    origin.update(file=m.archive, sha256=checksums[m.archive], verified=False)
                found.append(SourceInput(m, root, origin))
                break
        else:
            if log is not None:
                log(f"[yellow]no data for source {m.source!r} in {mocap_dir} (map {m.path})")
    # Hash the archives while tar runs.
    for m, archive, dest, proc in pending:
        digest = sha256_file(archive)
        expected = checksums.get(archive.name)
        if expected is not None and expected != digest:
            raise BuildError(
                f"{archive}: sha256 {digest} does not match SHA256SUMS ({expected}); "
                "the archive is corrupt or not the documented one"
            )
        if expected is None and log is not None:
            log(f"[yellow]{archive.name}: not listed in SHA256SUMS, checksum not verified")
        if proc is None:
            with tarfile.open(archive) as tf:
                tf.extractall(dest, filter="data")
        else:
            _, err = proc.communicate()
            if proc.returncode != 0:
                raise BuildError(f"{archive}: tar failed: {err.decode(errors='replace').strip()}")
        found.append(
            SourceInput(
                m,
                dest,
                {
                    "kind": "archive",
                    "file": archive.name,
                    "sha256": digest,
                    "verified": expected is not None,
                },
            )
        )
    found.sort(key=lambda s: s.map.source)
    return found


# --------------------------------------------------------------------------- splits


def assign_splits(
    names: Sequence[str],
    sources: Sequence[str],
    contents: Sequence[str],
    seed: int,
    fractions: dict[str, float] | None = None,
    *,
    actors: Sequence[str] | None = None,
    fixed: Sequence[str] | None = None,
) -> npt.NDArray[np.str_]:
    """Split clips by clip, stratified by (source, content, actor), deterministic from
    ``seed``. A clip whose ``fixed`` entry is a split name (``holdout``, or a split a map
    forces) goes there and takes no part in the strata; ``holdout`` is never assigned
    otherwise.

    Per stratum of n clips (shuffled by a generator seeded with ``seed`` and the stratum):
    n = 1 -> test; n = 2 -> 1 test + 1 train; n >= 3 -> max(1, round(n * f_test)) test,
    max(1, round(n * f_val)) val, the rest train. So every source, content and actor appears
    in test, and in val where it has at least 3 clips. Independent of clip order. (An empty
    actor leaves the stratum, and so the split, as it was before actors were used.)
    """
    fr = fractions or SPLIT_FRACTIONS
    out = np.full(len(names), "train", dtype="<U7")
    given = [""] * len(names) if fixed is None else list(fixed)
    if len(given) != len(names):
        raise ValueError(f"fixed has {len(given)} entries for {len(names)} clips")
    held = np.array([bool(g) for g in given], dtype=bool)
    for i, g in enumerate(given):
        if g:
            out[i] = g
    who = [""] * len(names) if actors is None else list(actors)
    strata: dict[tuple[str, str, str], list[int]] = defaultdict(list)
    for i, key in enumerate(zip(sources, contents, who, strict=True)):
        if not held[i]:
            strata[key].append(i)
    for (source, content, actor), idx in strata.items():
        idx = sorted(idx, key=lambda i: names[i])
        stratum = f"{source}\0{content}" + (f"\0{actor}" if actor else "")
        crc = zlib.crc32(stratum.encode())
        rng = np.random.default_rng([seed & 0xFFFFFFFF, crc])
        order = [idx[i] for i in rng.permutation(len(idx))]
        n = len(order)
        if n <= 2:
            n_test, n_val = 1, 0
        else:
            n_test = max(1, round(n * fr["test"]))
            n_val = max(1, round(n * fr["val"]))
        for i in order[:n_test]:
            out[i] = "test"
        for i in order[n_test : n_test + n_val]:
            out[i] = "val"
    return out


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
    maps_dir = Path(maps_dir) if maps_dir is not None else Path(__file__).parent.parent / "maps"
    maps = load_maps(maps_dir)
    say = log if log is not None else (lambda _msg: None)

    with ExitStack() as stack, _progress(progress) as bar:
        workdir = Path(tempfile.mkdtemp(prefix="marionette-mocap-"))
        stack.callback(shutil.rmtree, workdir, True)
        task = bar.add_task("extracting archives", total=None) if bar else None
        sources = locate_sources(mocap_dir, maps, workdir, log=say)
        if bar is not None and task is not None:
            bar.update(task, total=1, completed=1)
        if not sources:
            raise BuildError(f"{mocap_dir}: no mocap found for any map in {maps_dir}")

        jobs: list[ClipJob] = []
        skipped: list[dict[str, str]] = []
        for src in sources:
            files = _all_files(src.root)
            for rel in files:
                if not src.map.selects(rel):
                    continue
                label = f"{src.map.source}:{rel}"
                skeleton = None
                if src.map.reader == "asf":
                    try:
                        skeleton = str(src.root / pair_skeleton(src.map, rel, files))
                    except MapError as exc:
                        skipped.append({"file": label, "reason": str(exc)})
                        say(f"[yellow]skipped {label}: {exc}")
                        continue
                jobs.append(ClipJob(str(src.root / rel), rel, label, src.map, skeleton))
        # Largest files first: better load balance across workers.
        jobs.sort(key=lambda j: -os.path.getsize(j.path))
        infos = {}
        for job in list(jobs):
            try:
                infos[job.path] = job.map.clip_info(job.relpath)
            except MapError as exc:
                skipped.append({"file": job.label, "reason": str(exc)})
                say(f"[yellow]skipped {job.label}: {exc}")
                jobs.remove(job)
        names = Counter(i.name for i in infos.values())
        dupes = sorted(n for n, c in names.items() if c > 1)
        if dupes:
            raise BuildError(
                f"clip names are not unique: {dupes[:5]} (fix the map's name template)"
            )

        results: list[ClipResult] = []
        task = bar.add_task("reading clips", total=len(jobs)) if bar else None
        for res in _iter_results(jobs, workers):
            if res.error is not None:
                skipped.append({"file": res.job.label, "reason": res.error})
                say(f"[yellow]skipped {res.error}")
            elif res.positions is None or len(res.positions) == 0:
                reason = "no frames left after resampling and the drop rule"
                skipped.append({"file": res.job.label, "reason": reason})
                say(f"[yellow]skipped {res.job.label}: {reason}")
                results.append(res)
            else:
                results.append(res)
            if bar is not None and task is not None:
                bar.advance(task)

    # Deterministic order: by clip name, whatever order the workers finished in.
    results.sort(key=lambda r: infos[r.job.path].name)
    kept = [r for r in results if r.positions is not None and len(r.positions)]
    if not kept:
        raise BuildError("no frames survived; see the skipped files above")
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
            {"source": s.map.source, "file": _display_path(s.map.path), "sha256": s.map.sha256}
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
    meta["build_seconds"] = round(time.perf_counter() - t0, 1)
    out = save_dataset(out, dataset)
    return BuildReport(meta=meta, dataset=dataset, out=out)


def _group_by_actor(
    kept: Sequence[ClipResult], infos: dict[str, Any]
) -> dict[tuple[str, str], list[ClipResult]]:
    groups: dict[tuple[str, str], list[ClipResult]] = defaultdict(list)
    for r in kept:
        groups[(r.job.map.source, infos[r.job.path].actor)].append(r)
    return dict(sorted(groups.items()))


def _display_path(path: str) -> str:
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


# --------------------------------------------------------------------------- summary


def summary_tables(report: BuildReport) -> list[Any]:
    """Rich tables: clips/frames per source and split, drops, mean bone lengths."""
    from rich.table import Table

    ds, meta = report.dataset, report.meta
    sources = sorted(set(ds.clip_source.tolist()))
    counts = Table(title=f"{report.out}: clips / frames (30 fps) per source and split")
    counts.add_column("source")
    for s in SPLITS:
        counts.add_column(s, justify="right")
    counts.add_column("total", justify="right")
    frame_split = ds.clip_split[ds.clip]
    frame_source = ds.clip_source[ds.clip]
    for source in [*sources, "all"]:
        row = [source]
        csel = np.ones(ds.num_clips, bool) if source == "all" else ds.clip_source == source
        fsel = np.ones(len(ds), bool) if source == "all" else frame_source == source
        for split in SPLITS:
            nc = int((csel & (ds.clip_split == split)).sum())
            nf = int((fsel & (frame_split == split)).sum())
            row.append(f"{nc} / {nf:,}")
        row.append(f"{int(csel.sum())} / {int(fsel.sum()):,}")
        counts.add_row(*row)

    drops = Table(title="frames: source (native fps) -> 30 fps -> dropped -> kept")
    drops.add_column("source")
    for col in ("native", "at 30 fps", *DROP_REASONS, "kept", "files skipped"):
        drops.add_column(col, justify="right")
    skipped_by_source = Counter(f["file"].split(":", 1)[0] for f in meta["skipped_files"])
    for source in sorted(meta["dropped_frames_by_source"]):
        per = meta["dropped_frames_by_source"][source]
        drops.add_row(
            source,
            f"{meta['source_frames'].get(source, 0):,}",
            f"{meta['resampled_frames'].get(source, 0):,}",
            *[f"{per[r]:,}" for r in DROP_REASONS],
            f"{int((frame_source == source).sum()):,}",
            str(skipped_by_source.get(source, 0)),
        )

    bones = Table(title="mean bone lengths (m), bone named by its child joint")
    bones.add_column("bone")
    for source in sources:
        bones.add_column(source, justify="right")
    for b in BONE_NAMES:
        bones.add_row(b, *[f"{meta['mean_bone_lengths_m'][s][b]:.3f}" for s in sources])
    return [counts, drops, bones]


#: Plausible medians of a source's poses (canonical frame, metres): the thigh's length, the
#: head's height over the pelvis, the toes ahead of the ankles. Outside them a map's units,
#: up axis or sides are likely wrong (inches read as cm gave 11 cm thighs; +Z read as +Y,
#: figures lying down, the head 2 mm over the pelvis; sides swapped, toes 10 cm behind).
PLAUSIBLE: Final = {"thigh": (0.2, 0.7), "head": (0.2, 1.2), "toes": (0.0, 0.4)}


def sanity_warnings(ds: PoseDataset) -> list[str]:
    """What a source's poses say of its map, where implausible (a warning each); and a
    split the training needs (train, val) without frames."""
    out = []
    j = JOINT_INDEX
    for source in sorted(set(ds.clip_source.tolist())):
        p = ds.positions[ds.clip_source[ds.clip] == source][::10].astype(np.float64)
        thigh = float(np.median(np.linalg.norm(p[:, j["left_knee"]] - p[:, j["left_hip"]], axis=1)))
        head = float(np.median(p[:, j["head"], 1] - p[:, j["pelvis"], 1]))
        toes = float(np.median(p[:, [j["left_foot"], j["right_foot"]], 2]
                               - p[:, [j["left_ankle"], j["right_ankle"]], 2]))  # fmt: skip
        checks = (
            ("thigh", thigh, "the thigh is {v:.3f} m long: are the map's `unit` right?"),
            ("head", head, "the head is {v:.3f} m above the pelvis: is the map's `up_axis` right?"),
            ("toes", toes, "the toes are {v:.3f} m ahead of the ankles (facing +Z): are left and "
             "right swapped (`swap_sides`)?"),
        )  # fmt: skip
        for key, value, text in checks:
            lo, hi = PLAUSIBLE[key]
            if not lo <= value <= hi:
                out.append(f"{source}: median " + text.format(v=value))
    for split in ("train", "val"):
        if not (ds.clip_split == split).any():
            out.append(f"no {split} clips: training refuses this dataset (docs/data.md, splits)")
    return out


def print_summary(report: BuildReport, console: Any = None) -> None:
    from rich.console import Console

    console = console or Console()
    for table in summary_tables(report):
        console.print(table)
    meta = report.meta
    for item in meta["skipped_files"]:
        console.print(f"skipped: {item['reason']}")
    for warning in sanity_warnings(report.dataset):
        console.print(f"[yellow]warning: {warning}")
    console.print(
        f"{meta['num_clips']} clips, {meta['num_frames']:,} poses ({NUM_JOINTS} joints) -> "
        f"{report.out} ({report.out.stat().st_size / 2**20:.1f} MiB) "
        f"in {meta['build_seconds']:.1f} s"
    )
