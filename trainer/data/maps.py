"""Joint maps: one TOML file per mocap source (``trainer/maps/*.toml``).

A map says where a source's files are (archive name, include/exclude globs), how to read
them (unit, up axis, frame-rate overrides, swapped sides), how to name clips and derive their
metadata from the path, and which source joint (or ``<Joint>_end`` End Site) feeds each of
the 21 canonical joints. The format is documented in ``docs/data.md``.
"""

from __future__ import annotations

import hashlib
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_NAMES, MIRROR

MAP_FORMAT = 1

#: Metres per file unit.
UNITS: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "in": 0.0254, "ft": 0.3048}

#: Rotation taking a source's up axis to +Y (right-handed to right-handed).
UP_AXES: dict[str, tuple[tuple[float, float, float], ...]] = {
    "+Y": ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
    # Z-up: (x, y, z) -> (x, z, -y), a -90 degree turn about +X.
    "+Z": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0), (0.0, -1.0, 0.0)),
}

_TOP_KEYS = {
    "format",
    "source",
    "description",
    "licence",
    "archive",
    "unit",
    "up_axis",
    "swap_sides",
    "include",
    "exclude",
    "fps_override",
    "metadata",
    "joints",
}
_META_KEYS = {"pattern", "name", "content", "style", "actor"}


class MapError(ValueError):
    """An invalid joint-map file (names the file and the problem)."""


def glob_to_regex(pattern: str) -> re.Pattern[str]:
    """Compile a path glob: ``*`` and ``?`` stay within one folder, ``**`` crosses folders."""
    out: list[str] = []
    i = 0
    while i < len(pattern):
        c = pattern[i]
        if pattern.startswith("**/", i):
            out.append("(?:.*/)?")
            i += 3
            continue
        if pattern.startswith("**", i):
            out.append(".*")
            i += 2
            continue
        if c == "*":
            out.append("[^/]*")
        elif c == "?":
            out.append("[^/]")
        elif c == "[":
            end = pattern.find("]", i + 1)
            if end < 0:
                out.append(re.escape(c))
            else:
                body = pattern[i + 1 : end]
                if body.startswith("!"):
                    body = "^" + body[1:]
                out.append(f"[{body}]")
                i = end
        else:
            out.append(re.escape(c))
        i += 1
    return re.compile("".join(out) + r"\Z")


@dataclass(frozen=True)
class ClipInfo:
    """Metadata of one clip, derived from its path by a map's ``[metadata]`` section."""

    name: str
    source: str
    content: str
    style: str
    actor: str


@dataclass(frozen=True)
class MocapMap:
    """A parsed, validated joint map."""

    path: str
    sha256: str
    source: str
    description: str
    licence: str
    archive: str | None
    unit: str
    scale: float
    up_axis: str
    swap_sides: bool
    include: tuple[str, ...]
    exclude: tuple[str, ...]
    fps_overrides: tuple[tuple[str, float], ...]
    pattern: str
    templates: tuple[tuple[str, str], ...]  # (field, template) for name/content/style/actor
    joints: tuple[str, ...]  # source joint per canonical joint, as written (canonical order)

    @property
    def source_joints(self) -> tuple[str, ...]:
        """Source joint feeding each canonical joint, with ``swap_sides`` applied."""
        if not self.swap_sides:
            return self.joints
        return tuple(self.joints[MIRROR[i]] for i in range(len(JOINT_NAMES)))

    @property
    def up_matrix(self) -> npt.NDArray[np.float64]:
        return np.asarray(UP_AXES[self.up_axis], dtype=np.float64)

    @property
    def archive_stem(self) -> str | None:
        if self.archive is None:
            return None
        name = self.archive
        for ext in (".tar.xz", ".tar.gz", ".tar.bz2", ".tgz", ".tar", ".zip"):
            if name.endswith(ext):
                return name[: -len(ext)]
        return name

    def selects(self, relpath: str) -> bool:
        """Whether a file (path relative to the source root, with '/') is a clip to read."""
        if not any(glob_to_regex(p).match(relpath) for p in self.include):
            return False
        return not any(glob_to_regex(p).match(relpath) for p in self.exclude)

    def fps_for(self, relpath: str, header_fps: float) -> float:
        """The true frame rate of a file: the first matching override, else the header's."""
        for pattern, fps in self.fps_overrides:
            if glob_to_regex(pattern).match(relpath):
                return fps
        return header_fps

    def clip_info(self, relpath: str) -> ClipInfo:
        """Clip name and metadata from the path; ``MapError`` if the pattern does not match."""
        match = re.match(self.pattern, relpath)
        if match is None:
            raise MapError(f"{self.path}: [metadata] pattern does not match {relpath!r}")
        groups = {k: (v or "") for k, v in match.groupdict().items()}
        groups.setdefault("source", self.source)
        values: dict[str, str] = {}
        for key, template in self.templates:
            try:
                values[key] = template.format(**groups)
            except (KeyError, IndexError, ValueError) as exc:
                raise MapError(f"{self.path}: [metadata] {key} = {template!r}: {exc}") from None
        return ClipInfo(
            name=values["name"],
            source=self.source,
            content=values.get("content", ""),
            style=values.get("style", ""),
            actor=values.get("actor", ""),
        )


def _str_list(data: dict[str, Any], key: str, file: str) -> tuple[str, ...]:
    value = data.get(key, [])
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise MapError(f"{file}: {key!r} must be a list of glob strings")
    return tuple(value)


def load_map(path: str | Path) -> MocapMap:
    """Read and validate one map file (``MapError`` naming the file and the problem)."""
    path = Path(path)
    file = str(path)
    try:
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode("utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise MapError(f"{file}: cannot read map: {exc}") from None

    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise MapError(f"{file}: unknown keys {unknown}; known: {sorted(_TOP_KEYS)}")
    if data.get("format", MAP_FORMAT) != MAP_FORMAT:
        raise MapError(f"{file}: format {data.get('format')!r} is not supported (want 1)")
    source = data.get("source")
    if not isinstance(source, str) or not re.fullmatch(r"[a-z0-9][a-z0-9._-]*", source):
        raise MapError(f"{file}: 'source' must be a lower-case slug like 'my-studio'")

    unit = data.get("unit", "m")
    if isinstance(unit, int | float) and not isinstance(unit, bool) and unit > 0:
        scale, unit_name = float(unit), f"{float(unit)} m"
    elif isinstance(unit, str) and unit in UNITS:
        scale, unit_name = UNITS[unit], unit
    else:
        raise MapError(f"{file}: 'unit' must be one of {sorted(UNITS)} or metres per unit")
    up_axis = data.get("up_axis", "+Y")
    if up_axis not in UP_AXES:
        raise MapError(f"{file}: 'up_axis' must be one of {sorted(UP_AXES)}")
    swap_sides = data.get("swap_sides", False)
    if not isinstance(swap_sides, bool):
        raise MapError(f"{file}: 'swap_sides' must be true or false")
    archive = data.get("archive")
    if archive is not None and not isinstance(archive, str):
        raise MapError(f"{file}: 'archive' must be a file name")

    include = _str_list(data, "include", file)
    if not include:
        raise MapError(f"{file}: 'include' needs at least one glob pattern")
    exclude = _str_list(data, "exclude", file)

    overrides: list[tuple[str, float]] = []
    for item in data.get("fps_override", []):
        if (
            not isinstance(item, dict)
            or set(item) != {"glob", "fps"}
            or not isinstance(item["glob"], str)
            or not isinstance(item["fps"], int | float)
            or item["fps"] <= 0
        ):
            raise MapError(f"{file}: each [[fps_override]] needs glob = '...' and fps > 0")
        overrides.append((item["glob"], float(item["fps"])))

    meta = data.get("metadata", {})
    if not isinstance(meta, dict):
        raise MapError(f"{file}: [metadata] must be a table")
    unknown = sorted(set(meta) - _META_KEYS)
    if unknown:
        raise MapError(f"{file}: unknown [metadata] keys {unknown}; known: {sorted(_META_KEYS)}")
    pattern = meta.get("pattern", r"^(?P<path>.*?)(?:\.bvh)?$")
    try:
        re.compile(pattern)
    except re.error as exc:
        raise MapError(f"{file}: [metadata] pattern: {exc}") from None
    templates = {
        "name": meta.get("name", "{source}/{path}"),
        "content": meta.get("content", ""),
        "style": meta.get("style", ""),
        "actor": meta.get("actor", ""),
    }
    if not all(isinstance(v, str) for v in templates.values()):
        raise MapError(f"{file}: [metadata] templates must be strings")

    joints = data.get("joints")
    if not isinstance(joints, dict):
        raise MapError(f"{file}: missing [joints] table")
    unknown = sorted(set(joints) - set(JOINT_NAMES))
    missing = [n for n in JOINT_NAMES if n not in joints]
    if unknown or missing:
        raise MapError(
            f"{file}: [joints] must map exactly the 21 canonical joints; "
            f"missing {missing}, unknown {unknown}"
        )
    if not all(isinstance(v, str) and v for v in joints.values()):
        raise MapError(f"{file}: [joints] values must be source joint names")

    return MocapMap(
        path=file,
        sha256=hashlib.sha256(raw).hexdigest(),
        source=source,
        description=str(data.get("description", "")),
        licence=str(data.get("licence", "")),
        archive=archive,
        unit=unit_name,
        scale=scale,
        up_axis=up_axis,
        swap_sides=swap_sides,
        include=include,
        exclude=exclude,
        fps_overrides=tuple(overrides),
        pattern=pattern,
        templates=tuple(templates.items()),
        joints=tuple(joints[n] for n in JOINT_NAMES),
    )


def load_maps(folder: str | Path) -> list[MocapMap]:
    """All ``*.toml`` maps of a folder, sorted by file name; sources must be unique."""
    folder = Path(folder)
    files = sorted(folder.glob("*.toml"))
    if not files:
        raise MapError(f"{folder}: no *.toml joint maps found")
    maps = [load_map(f) for f in files]
    seen: dict[str, str] = {}
    for m in maps:
        if m.source in seen:
            raise MapError(f"{m.path}: source {m.source!r} is also defined by {seen[m.source]}")
        seen[m.source] = m.path
    return maps
