"""Where each map's data is: an archive (its sha256 checked against ``SHA256SUMS``, all
extracted in parallel) or an extracted folder (its files hashed), for
:func:`trainer.data.build.build_dataset`; the files a map selects, and an ASF skeleton
paired with its AMC motions."""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tarfile
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from core.io import sha256_file
from trainer.data.checks import no_match_message, not_found_message
from trainer.data.maps import MapError, MocapMap, glob_to_regex


class BuildError(RuntimeError):
    """The dataset cannot be built (no data, checksum mismatch, bad maps...)."""


@dataclass
class SourceInput:
    map: MocapMap
    root: Path
    origin: dict[str, Any]  # provenance: archive (+sha256) or folder
    files: list[str] = field(default_factory=list)  # every file under root (relative)

    @property
    def selected(self) -> list[str]:
        """The files the map selects (include, not exclude)."""
        return [rel for rel in self.files if self.map.selects(rel)]


@dataclass
class Located:
    """What :func:`locate_sources` found: the sources, and messages for the maps whose data
    is missing, or found but with no file the map's include globs select."""

    sources: list[SourceInput] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    unmatched: list[str] = field(default_factory=list)
    shadowed: list[str] = field(default_factory=list)


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


def _all_files(root: Path, *, follow: bool = False) -> list[str]:
    """Every file under ``root``, as sorted '/'-separated relative paths; ``follow``: through
    symbolic links to folders too (an extracted folder assembled from links to a NAS: its
    linked actor folders were silently not read, a studio audit, D1), each real folder once:
    a link to a folder inside ``root`` (read as itself) or to one already read is not
    walked (a link back to an ancestor looped)."""
    out: list[str] = []
    inside = os.path.realpath(root)
    seen: set[str] = set()

    def new(dirpath: str, name: str) -> bool:
        path = os.path.join(dirpath, name)
        real = os.path.realpath(path)
        if os.path.islink(path) and (real == inside or real.startswith(inside + os.sep)):
            return False
        return real not in seen

    for dirpath, dirnames, filenames in os.walk(root, followlinks=follow):
        if follow:
            seen.add(os.path.realpath(dirpath))
            dirnames[:] = [d for d in dirnames if new(dirpath, d)]
        dirnames.sort()
        rel_dir = Path(dirpath).relative_to(root).as_posix()
        for name in sorted(filenames):
            out.append(name if rel_dir == "." else f"{rel_dir}/{name}")
    return out


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


def _refuse_zip(archive: Path, mocap_map: MocapMap) -> None:
    """A zip archive is refused in one line (tar printed "This does not look like a tar
    archive" and more)."""
    if archive.suffix.lower() == ".zip" or zipfile.is_zipfile(archive):
        raise BuildError(
            f"{archive}: a zip archive (map {mocap_map.path}); the builder reads tar archives "
            "(.tar, .tar.gz, .tgz, .tar.bz2, .tar.xz) or an extracted folder: repack it as "
            f".tar.xz or unzip it into {archive.parent / (mocap_map.archive_stem or '')}/"
        )


def _folder_source(
    mocap_map: MocapMap, roots: Sequence[Path], checksums: dict[str, str]
) -> SourceInput | None:
    """The first of ``roots`` (extracted folders) holding files the map selects."""
    for root in roots:
        if not root.is_dir():
            continue
        files = _all_files(root, follow=True)
        selected = [rel for rel in files if mocap_map.selects(rel)]
        if selected:
            origin: dict[str, Any] = {
                "kind": "folder", "path": str(root), "files": len(selected),
                "files_sha256": folder_digest(root, selected),
            }  # fmt: skip
            if mocap_map.archive and mocap_map.archive in checksums:
                # Not verifiable from a folder: the sum SHA256SUMS lists for its archive.
                archive = mocap_map.archive
                origin.update(file=archive, sha256=checksums[archive], verified=False)
            return SourceInput(mocap_map, root, origin, files)
    return None


def _shadowed_folder(mocap_map: MocapMap, roots: Sequence[Path]) -> tuple[Path, int] | None:
    """The extracted folder that :func:`_folder_source` would read if the map's archive
    were not beside it, with its count of files the map selects (an archive silently won
    over a same-named folder with more takes: a studio audit, D10)."""
    for root in roots:
        if root.is_dir():
            count = sum(mocap_map.selects(rel) for rel in _all_files(root, follow=True))
            if count:
                return root, count
    return None


def _extracted_source(
    mocap_map: MocapMap,
    archive: Path,
    dest: Path,
    proc: subprocess.Popen[bytes] | None,
    checksums: dict[str, str],
    log: Any,
) -> SourceInput:
    """Check an archive's sha256 (while tar runs), wait for its extraction into ``dest``."""
    digest = sha256_file(archive)
    expected = checksums.get(archive.name)
    if expected is not None and expected != digest:
        raise BuildError(
            f"{archive}: sha256 {digest} does not match SHA256SUMS ({expected}); "
            "the archive is corrupt or not the documented one"
        )
    sums = archive.parent / "SHA256SUMS"
    if expected is None and log is not None:
        from rich.markup import escape

        if sums.is_file():
            log(f"[yellow]{escape(archive.name)}: not listed in SHA256SUMS, checksum not verified")
        else:  # (it said "not listed in SHA256SUMS" of a file that is not there)
            log(f"[yellow]no SHA256SUMS in {escape(str(archive.parent))}: checksum of "
                f"{escape(archive.name)} not verified")  # fmt: skip
    if proc is None:
        with tarfile.open(archive) as tf:
            tf.extractall(dest, filter="data")
    else:
        _, err = proc.communicate()
        if proc.returncode != 0:
            first = err.decode(errors="replace").strip().splitlines()[:1]
            raise BuildError(f"{archive}: tar failed: {' '.join(first)}")
    origin: dict[str, Any] = {"kind": "archive", "file": archive.name, "sha256": digest}
    if expected is None and not sums.is_file():
        origin["sha256sums"] = "absent"  # (the card: no SHA256SUMS, not "not listed")
    return SourceInput(
        mocap_map, dest, dict(origin, verified=expected is not None), _all_files(dest)
    )


def locate_sources(
    mocap_dir: Path,
    maps: Sequence[MocapMap],
    workdir: Path,
    log: Any = None,
    *,
    required: bool = False,
) -> Located:
    """Find each map's data: ``<mocap>/<archive>`` (extracted into ``workdir``, all archives
    in parallel), else an extracted folder ``<mocap>/<archive stem>/`` or ``<mocap>/``.
    ``required``: a map whose data is not found is a ``BuildError`` (before extracting)."""
    checksums = read_checksums(mocap_dir)
    archives: list[tuple[MocapMap, Path]] = []
    located = Located()
    for m in maps:
        archive = mocap_dir / m.archive if m.archive else None
        stem = mocap_dir / m.archive_stem if m.archive_stem else None
        roots = [r for r in (stem, mocap_dir) if r is not None]
        if archive is not None and archive.is_file():
            _refuse_zip(archive, m)
            archives.append((m, archive))
            if (beside := _shadowed_folder(m, roots)) is not None:
                located.shadowed.append(
                    f"map {m.path}: both the archive {archive} and the extracted folder "
                    f"{beside[0]}/ ({beside[1]} files the map selects) are in {mocap_dir}: the "
                    "archive was read, the folder not; move the one not to read out of "
                    "--mocap"
                )
            continue
        if (src := _folder_source(m, roots, checksums)) is not None:
            located.sources.append(src)
        elif stem is not None and stem.is_dir():
            located.unmatched.append(
                no_match_message(m, f"folder {stem}", _all_files(stem, follow=True))
            )
        else:
            taken = {n for o in maps if o is not m for n in (o.archive, o.archive_stem) if n}
            located.missing.append(not_found_message(m, mocap_dir, taken))
    if required and located.missing:
        head = "sources not found (with --maps, every map's data is needed):"
        raise BuildError("\n".join([head, *located.missing]))
    pending = [(m, a, workdir / m.source) for m, a in archives]
    procs = [_start_extract(archive, dest) for _, archive, dest in pending]
    for (m, archive, dest), proc in zip(pending, procs, strict=True):
        src = _extracted_source(m, archive, dest, proc, checksums, log)
        if any(m.selects(f) for f in src.files):
            located.sources.append(src)
        else:
            located.unmatched.append(no_match_message(m, archive.name, src.files))
    located.sources.sort(key=lambda s: s.map.source)
    return located
