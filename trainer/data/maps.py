"""Joint maps: one TOML file per mocap source (``trainer/maps/*.toml``).

A map says where a source's files are (archive name, include/exclude globs), how to read
them (reader: BVH or ASF/AMC; unit, up axis, frame rate, swapped sides, per-file overrides),
how to name clips and derive their metadata from the path, which clips are held out of
training, and which source joint (or ``<Joint>_end`` End Site, or a point part-way between
two source joints) feeds each of the 21 canonical joints. The format is documented in
``docs/data.md``.
"""

from __future__ import annotations

import functools
import hashlib
import math
import re
import string
import tomllib
from collections.abc import Collection, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Protocol

import numpy as np
import numpy.typing as npt

from core.skeleton import JOINT_NAMES, MIRROR
from core.text import QUOTE, clip, close_match
from core.units import UNITS, UP_AXES
from trainer.config import toml_float

MAP_FORMAT = 2

#: Units (``core.units.UNITS``, metres per file unit) and one more: ``asf``, from the ASF
#: skeleton's ``:units length`` (CMU: values are inches x 0.45, so metres = value x 0.0254 /
#: 0.45); only with ``reader = "asf"``. Up axes are ``core.units.UP_AXES``.
ASF_UNIT = "asf"
READERS: tuple[str, ...] = ("bvh", "asf")
ROOT_POSITIONS: tuple[str, ...] = ("replace", "add")

_TOP_KEYS = {
    "format",
    "source",
    "description",
    "licence",
    "archive",
    "reader",
    "skeleton",
    "unit",
    "up_axis",
    "root_position",
    "swap_sides",
    "include",
    "exclude",
    "holdout",
    "override",
    "metadata",
    "joints",
}
_META_KEYS = {"pattern", "name", "content", "style", "actor"}
_OVERRIDE_KEYS = {
    "glob",
    "fps",
    "unit",
    "up_axis",
    "joints",
    "content",
    "style",
    "actor",
    "split",
}
#: Splits an override may force (``holdout`` is set by the ``holdout`` globs).
FIXED_SPLITS: tuple[str, ...] = ("train", "val", "test")


class MapError(ValueError):
    """An invalid joint-map file (names the file and the problem)."""


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest candidate, or ``""``."""
    match = close_match(name, candidates)
    return f"; did you mean {match!r}?" if match is not None else ""


class Reader(Protocol):
    """What a map needs of a parsed file (:class:`core.bvh.BVH`, :class:`trainer.data.asf.AMC`)."""

    @property
    def joint_names(self) -> tuple[str, ...]: ...

    def forward_kinematics(
        self,
        names: Sequence[str] | None = None,
        frames: slice | npt.NDArray[np.integer] | None = None,
    ) -> npt.NDArray[np.float64]: ...


@functools.lru_cache(maxsize=1024)
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


def _matches(patterns: Sequence[str], relpath: str) -> bool:
    return any(glob_to_regex(p).match(relpath) for p in patterns)


@dataclass(frozen=True)
class JointSource:
    """Where a canonical joint comes from: a source joint, or the point ``at`` of the way
    from ``joint`` to ``towards`` (``joint + at * (towards - joint)``)."""

    joint: str
    towards: str | None = None
    at: float = 0.0

    @property
    def names(self) -> tuple[str, ...]:
        return (self.joint,) if self.towards is None else (self.joint, self.towards)

    def __str__(self) -> str:
        if self.towards is None:
            return self.joint
        return f"{self.at:g} of {self.joint} -> {self.towards}"


def joint_positions(
    reader: Reader,
    joints: Sequence[JointSource],
    frames: slice | npt.NDArray[np.integer] | None = None,
) -> npt.NDArray[np.float64]:
    """World positions ``[F, len(joints), 3]`` (file units) of the mapped joints: one FK
    pass over the source joints they need, then the part-way points interpolated."""
    names = list(dict.fromkeys(n for j in joints for n in j.names))
    fk = reader.forward_kinematics(names, frames=frames)
    col = {n: k for k, n in enumerate(names)}
    out = np.empty((fk.shape[0], len(joints), 3), dtype=np.float64)
    for k, j in enumerate(joints):
        a = fk[:, col[j.joint]]
        out[:, k] = a if j.towards is None else a + j.at * (fk[:, col[j.towards]] - a)
    return out


@dataclass(frozen=True)
class ClipInfo:
    """Metadata of one clip, derived from its path by a map's ``[metadata]`` section."""

    name: str
    source: str
    content: str
    style: str
    actor: str


@dataclass(frozen=True)
class Override:
    """One ``[[override]]`` entry: settings for the files its glob matches."""

    glob: str
    values: tuple[tuple[str, Any], ...]  # (key, value), keys from _OVERRIDE_KEYS - {glob}

    def get(self, key: str) -> Any:
        return dict(self.values).get(key)


@dataclass(frozen=True)
class MocapMap:
    """A parsed, validated joint map."""

    path: str
    sha256: str
    source: str
    description: str
    licence: str
    archive: str | None
    reader: str  # "bvh" or "asf"
    skeleton: tuple[str, ...]  # ASF glob templates (reader "asf"), filled from [metadata] groups
    unit: str
    scale: float  # metres per unit; 0.0 for unit "asf" (from the skeleton)
    up_axis: str
    root_position: str  # "replace" (BVH standard) or "add" (root channels offset the OFFSET)
    swap_sides: bool
    include: tuple[str, ...]
    exclude: tuple[str, ...]
    holdout: tuple[str, ...]
    overrides: tuple[Override, ...]
    pattern: str
    templates: tuple[tuple[str, str], ...]  # (field, template) for name/content/style/actor
    joints: tuple[JointSource, ...]  # per canonical joint, as written (canonical order)

    # ------------------------------------------------------------------ per file

    def _override(self, relpath: str, key: str) -> Any:
        """The value of ``key`` from the first override matching ``relpath`` that sets it."""
        for o in self.overrides:
            value = o.get(key)
            if value is not None and glob_to_regex(o.glob).match(relpath):
                return value
        return None

    def joints_for(self, relpath: str) -> tuple[JointSource, ...]:
        """Source of each canonical joint for this file (overrides and ``swap_sides``
        applied), in canonical order."""
        table: dict[str, JointSource] | None = self._override(relpath, "joints")
        joints = list(self.joints)
        if table:
            joints = [table.get(n, j) for n, j in zip(JOINT_NAMES, joints, strict=True)]
        if self.swap_sides:
            joints = [joints[MIRROR[i]] for i in range(len(JOINT_NAMES))]
        return tuple(joints)

    @property
    def source_joints(self) -> tuple[str, ...]:
        """Source joint feeding each canonical joint (``swap_sides`` applied), for maps whose
        joints are all plain names (else use :meth:`joints_for` and :func:`joint_positions`)."""
        joints = self.joints_for("")
        if any(j.towards is not None for j in joints):
            raise MapError(f"{self.path}: part-way joints: use joints_for / joint_positions")
        return tuple(j.joint for j in joints)

    def joint_ref(self, name: str) -> str:
        """Where the map names source joint ``name``, as written: ``[joints] left_elbow =
        'forearm.l'`` or ``[[override]] #2 joints.left_elbow = ...`` (the first use)."""
        tables = [("[joints] ", dict(zip(JOINT_NAMES, self.joints, strict=True)))]
        for i, o in enumerate(self.overrides):
            tables.append((f"[[override]] #{i + 1} joints.", o.get("joints") or {}))
        for prefix, table in tables:
            for canon, j in table.items():
                if j.towards is None and j.joint == name:
                    return f"{prefix}{canon} = {name!r}"
                if name in j.names:
                    return f"{prefix}{canon} = {{ between = {list(j.names)!r} }}: {name!r}"
        return f"joint {name!r}"

    def scale_for(self, relpath: str, asf_metres_per_unit: float | None = None) -> float:
        """Metres per file unit for this file (``asf``: the skeleton's own unit)."""
        unit = self._override(relpath, "unit")
        scale = self.scale if unit is None else _unit_scale(unit)[0]
        if scale == 0.0:
            if asf_metres_per_unit is None:
                raise MapError(f"{self.path}: unit 'asf' needs an ASF skeleton ({relpath})")
            return asf_metres_per_unit
        return scale

    def up_axis_for(self, relpath: str) -> str:
        value = self._override(relpath, "up_axis")
        return str(value) if value is not None else self.up_axis

    def up_matrix_for(self, relpath: str) -> npt.NDArray[np.float64]:
        return np.array(UP_AXES[self.up_axis_for(relpath)])

    @property
    def up_matrix(self) -> npt.NDArray[np.float64]:
        return np.array(UP_AXES[self.up_axis])

    def fps_for(self, relpath: str, header_fps: float) -> float:
        """The true frame rate of a file: the first matching override, else the header's."""
        fps = self._override(relpath, "fps")
        return float(fps) if fps is not None else header_fps

    def is_holdout(self, relpath: str) -> bool:
        """Whether the file is held out of training (its clip goes to split ``holdout``)."""
        return _matches(self.holdout, relpath)

    def split_for(self, relpath: str) -> str:
        """The split the map fixes for a file: ``holdout``, an override's ``split``, or ''
        (the builder's stratified split decides)."""
        if self.is_holdout(relpath):
            return "holdout"
        return str(self._override(relpath, "split") or "")

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
        return _matches(self.include, relpath) and not _matches(self.exclude, relpath)

    def _groups(self, relpath: str) -> dict[str, str]:
        match = re.match(self.pattern, relpath)
        if match is None:
            raise MapError(f"{self.path}: [metadata] pattern does not match {relpath!r}")
        groups = {k: (v or "") for k, v in match.groupdict().items()}
        groups.setdefault("source", self.source)
        groups.setdefault("dir", relpath.rpartition("/")[0])
        return groups

    def clip_info(self, relpath: str) -> ClipInfo:
        """Clip name and metadata from the path; ``MapError`` if the pattern does not match."""
        groups = self._groups(relpath)
        values: dict[str, str] = {}
        for key, template in self.templates:
            override = self._override(relpath, key)
            if override is not None:
                template = str(override)
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

    def skeleton_globs(self, relpath: str) -> list[str]:
        """The ``skeleton`` templates filled for one motion file (globs relative to the
        source root; the builder requires exactly one file to match any of them)."""
        if not self.skeleton:
            raise MapError(f"{self.path}: no 'skeleton' template (needed by reader 'asf')")
        groups = self._groups(relpath)
        try:
            return [t.format(**groups) for t in self.skeleton]
        except (KeyError, IndexError, ValueError) as exc:
            raise MapError(f"{self.path}: skeleton = {list(self.skeleton)!r}: {exc}") from None


# --------------------------------------------------------------------------- parsing


def _str_list(data: dict[str, Any], key: str, file: str) -> tuple[str, ...]:
    value = data.get(key, [])
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise MapError(f"{file}: {key!r} must be a list of glob strings")
    return tuple(value)


def _unit_scale(unit: Any) -> tuple[float, str]:
    """``(metres per unit, display name)``; 0.0 for ``asf``; ``ValueError`` if invalid."""
    if isinstance(unit, int | float) and not isinstance(unit, bool) and 0 < unit < math.inf:
        return float(unit), f"{float(unit)} m"
    if isinstance(unit, str) and unit in UNITS:
        return UNITS[unit], unit
    if unit == ASF_UNIT:
        return 0.0, ASF_UNIT
    raise ValueError(unit)


def _parse_unit(unit: Any, where: str, reader: str) -> tuple[float, str]:
    try:
        scale, name = _unit_scale(unit)
    except ValueError:
        raise MapError(
            f"{where}: 'unit' must be one of {sorted(UNITS)}, 'asf' or metres per unit (a "
            f"finite number > 0), got {clip(repr(unit), QUOTE)}"
        ) from None
    if name == ASF_UNIT and reader != "asf":
        raise MapError(f"{where}: unit 'asf' needs reader = 'asf'")
    return scale, name


def _parse_joint(value: Any, where: str) -> JointSource:
    if isinstance(value, str) and value:
        return JointSource(value)
    if isinstance(value, dict):
        between, at = value.get("between"), value.get("at")
        if (
            set(value) == {"between", "at"}
            and isinstance(between, list)
            and len(between) == 2
            and all(isinstance(b, str) and b for b in between)
            and isinstance(at, int | float)
            and not isinstance(at, bool)
            and math.isfinite(at)
            and 0.0 <= at <= 1.0
        ):
            return JointSource(between[0], between[1], float(at))
        raise MapError(
            f'{where}: a part-way joint is {{ between = ["from", "to"], at = 0.25 }} '
            f"with 0 <= at <= 1, got {value!r}"
        )
    raise MapError(f"{where}: must be a source joint name or {{ between = [...], at = ... }}")


def _parse_joints(table: Any, where: str, complete: bool) -> dict[str, JointSource]:
    if not isinstance(table, dict):
        raise MapError(f"{where}: must be a table of canonical joint = source joint")
    unknown = sorted(set(table) - set(JOINT_NAMES))
    missing = [n for n in JOINT_NAMES if n not in table] if complete else []
    if unknown or missing:
        raise MapError(
            f"{where} must map exactly the 21 canonical joints; missing {missing}, "
            f"unknown {unknown}"
            if complete
            else f"{where}: unknown canonical joints {unknown}"
        )
    return {n: _parse_joint(v, f"{where} {n}") for n, v in table.items()}


def _check_distinct(joints: dict[str, JointSource], where: str, changed: Collection[str]) -> None:
    """Refuse two canonical joints fed by one source point (a copy-paste slip such as
    ``right_wrist = 'LeftHand'``): the bone between them has no length or stretches with the
    other side, so the build kept a zero bone or dropped most frames, without a word."""
    first: dict[JointSource, str] = {}
    for canon, source in joints.items():
        other = first.setdefault(source, canon)
        if other != canon and (canon in changed or other in changed):
            if canon not in changed:  # name the joint the table being checked sets
                canon, other = other, canon
            raise MapError(
                f"{where}{canon} = {str(source)!r} is also {other}'s source joint: "
                "each canonical joint needs a source joint of its own"
            )


def _up_axis_error(where: str, value: Any) -> str:
    """The message of an ``up_axis`` not one of :data:`UP_AXES`, with the value received
    (``"-Z"`` was refused without it: a studio audit, 2026-12-07)."""
    return (
        f"{where}: 'up_axis' must be one of {sorted(UP_AXES)}, got {clip(repr(value), QUOTE)}"
        + did_you_mean(str(value), UP_AXES)
    )


#: Names of a map key someone may write for it, which no spelling match finds.
_KEY_ALIASES: Final = {
    "frame_rate": "fps",
    "framerate": "fps",
    "frames_per_second": "fps",
    "rate": "fps",
    "frame_time": "fps",
    "up": "up_axis",
    "units": "unit",
    "scale": "unit",
    "license": "licence",
    "mirror": "swap_sides",
    "overrides": "override",
}


def _key_hint(name: str) -> str:
    """For an unknown top-level key: ``"; 'frame_rate': did you mean 'fps'? ..."`` where a
    known key resembles it (by spelling or :data:`_KEY_ALIASES`; an override's, as ``fps``,
    with how to set it), else '' (a studio audit, 2026-12-07: ``frame_rate`` suggested
    nothing)."""
    key = _KEY_ALIASES.get(name.casefold()) or close_match(name, _TOP_KEYS | _OVERRIDE_KEYS)
    if key is None:
        return ""
    if key in _TOP_KEYS:
        return f"; {name!r}: did you mean {key!r}?"
    how = "it is set per file, in an [[override]]" + (
        f' (for every file: glob = "**", {key} = ...)' if key != "glob" else ""
    )
    return f"; {name!r}: {how}" if key == name else f"; {name!r}: did you mean {key!r}? {how}"


def _parse_override(item: Any, index: int, file: str, reader: str) -> Override:
    where = f"{file}: [[override]] #{index + 1}"
    if not isinstance(item, dict) or not isinstance(item.get("glob"), str):
        raise MapError(f"{where}: needs glob = '...'")
    unknown = sorted(set(item) - _OVERRIDE_KEYS)
    if unknown or len(item) < 2:
        raise MapError(
            f"{where}: unknown keys {unknown}; an override sets some of "
            f"{sorted(_OVERRIDE_KEYS - {'glob'})}"
        )
    values: dict[str, Any] = {}
    for key, value in item.items():
        if key == "glob":
            continue
        if key == "fps":
            if not isinstance(value, int | float) or isinstance(value, bool) or value <= 0:
                raise MapError(f"{where}: fps must be > 0, got {clip(repr(value), QUOTE)}")
            if not math.isfinite(value):  # (1e999: a Written, quoted as the file writes it)
                raise MapError(f"{where}: fps must be a finite number, got {value!r}")
            values[key] = float(value)
        elif key == "unit":
            _parse_unit(value, where, reader)
            values[key] = value
        elif key == "up_axis":
            if value not in UP_AXES:
                raise MapError(_up_axis_error(where, value))
            values[key] = value
        elif key == "joints":
            values[key] = _parse_joints(value, f"{where} joints", complete=False)
        elif key == "split":
            if value not in FIXED_SPLITS:
                raise MapError(f"{where}: split must be one of {list(FIXED_SPLITS)}")
            values[key] = value
        else:
            if not isinstance(value, str):
                raise MapError(f"{where}: {key} must be a string template")
            values[key] = value
    return Override(item["glob"], tuple(values.items()))


def _template_fields(template: str) -> list[str]:
    """The field names of a ``str.format`` template (``ValueError`` if malformed)."""
    fields = [f for _, f, _, _ in string.Formatter().parse(template) if f is not None]
    return [re.split(r"[.\[!:]", f, maxsplit=1)[0] for f in fields]


def _check_template(where: str, template: str, groups: Sequence[str]) -> None:
    """``MapError`` unless every ``{field}`` of ``template`` is one of ``groups``."""
    try:
        fields = _template_fields(template)
    except ValueError as exc:
        raise MapError(f"{where} = {template!r}: {exc}") from None
    for name in fields:
        if name not in groups:
            raise MapError(
                f"{where} = {template!r}: {{{name}}} is not a group of the [metadata] "
                f"pattern; its groups are {list(groups)}{did_you_mean(name, groups)}"
            )


def _check_templates(
    file: str,
    pattern: str,
    templates: dict[str, str],
    overrides: Sequence[Override],
    skeleton: Sequence[str],
) -> None:
    """Every template field must be a named group of the pattern (or ``source``, ``dir``):
    a typo (``{actr}``) skipped every file one by one at build time."""
    groups = [*re.compile(pattern).groupindex, "source", "dir"]
    for key, template in templates.items():
        _check_template(f"{file}: [metadata] {key}", template, groups)
    for i, o in enumerate(overrides):
        for key in ("content", "style", "actor"):
            value = o.get(key)
            if isinstance(value, str):
                _check_template(f"{file}: [[override]] #{i + 1} {key}", value, groups)
    for template in skeleton:
        _check_template(f"{file}: skeleton", template, groups)


def load_map(path: str | Path) -> MocapMap:
    """Read and validate one map file (``MapError`` naming the file and the problem)."""
    path = Path(path)
    file = str(path)
    try:
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode("utf-8"), parse_float=toml_float)
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise MapError(f"{file}: cannot read map: {exc}") from None

    if "format" not in data:
        raise MapError(f"{file}: missing `format = {MAP_FORMAT}` (the map format's version)")
    if data.get("format") != MAP_FORMAT:
        hint = (
            " (format 1: rename [[fps_override]] to [[override]])"
            if data.get("format") == 1
            else ""
        )
        raise MapError(
            f"{file}: format = {data.get('format')!r}; this reader wants {MAP_FORMAT}{hint}"
        )
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        hints = "".join(_key_hint(k) for k in unknown)
        raise MapError(f"{file}: unknown keys {unknown}; known: {sorted(_TOP_KEYS)}{hints}")
    source = data.get("source")
    if not isinstance(source, str) or not re.fullmatch(r"[a-z0-9][a-z0-9._-]*", source):
        raise MapError(f"{file}: 'source' must be a lower-case slug like 'my-studio'")

    reader = data.get("reader", "bvh")
    if reader not in READERS:
        raise MapError(f"{file}: 'reader' must be one of {list(READERS)}")
    skeleton = _str_list(data, "skeleton", file)
    if reader == "asf" and not skeleton:
        raise MapError(f"{file}: reader 'asf' needs skeleton = ['<ASF glob template>', ...]")
    if reader != "asf" and skeleton:
        raise MapError(f"{file}: 'skeleton' is only for reader = 'asf'")
    scale, unit_name = _parse_unit(data.get("unit", "m"), file, reader)
    up_axis = data.get("up_axis", "+Y")
    if up_axis not in UP_AXES:
        raise MapError(_up_axis_error(file, up_axis))
    root_position = data.get("root_position", "replace")
    if root_position not in ROOT_POSITIONS or (root_position == "add" and reader != "bvh"):
        raise MapError(f"{file}: 'root_position' must be one of {list(ROOT_POSITIONS)} (BVH)")
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
    holdout = _str_list(data, "holdout", file)
    items = data.get("override", [])
    if not isinstance(items, list):
        raise MapError(f"{file}: 'override' must be an array of tables ([[override]])")
    overrides = tuple(_parse_override(item, i, file, reader) for i, item in enumerate(items))

    meta = data.get("metadata", {})
    if not isinstance(meta, dict):
        raise MapError(f"{file}: [metadata] must be a table")
    unknown = sorted(set(meta) - _META_KEYS)
    if unknown:
        raise MapError(f"{file}: unknown [metadata] keys {unknown}; known: {sorted(_META_KEYS)}")
    default_pattern = r"^(?P<path>.*?)(?:\.(?:bvh|amc))?$"
    pattern = meta.get("pattern", default_pattern)
    try:
        re.compile(pattern)
    except (re.error, TypeError) as exc:
        raise MapError(f"{file}: [metadata] pattern: {exc}") from None
    templates = {
        "name": meta.get("name", "{source}/{path}"),
        "content": meta.get("content", ""),
        "style": meta.get("style", ""),
        "actor": meta.get("actor", ""),
    }
    if not all(isinstance(v, str) for v in templates.values()):
        raise MapError(f"{file}: [metadata] templates must be strings")
    _check_templates(file, pattern, templates, overrides, skeleton)

    if "joints" not in data:
        raise MapError(f"{file}: missing [joints] table")
    joints = _parse_joints(data["joints"], f"{file}: [joints]", complete=True)
    _check_distinct(joints, f"{file}: [joints] ", JOINT_NAMES)
    for i, o in enumerate(overrides):
        table: dict[str, JointSource] = o.get("joints") or {}
        merged = {n: table.get(n, j) for n, j in joints.items()}
        _check_distinct(merged, f"{file}: [[override]] #{i + 1} joints.", table)

    return MocapMap(
        path=file,
        sha256=hashlib.sha256(raw).hexdigest(),
        source=source,
        description=str(data.get("description", "")),
        licence=str(data.get("licence", "")),
        archive=archive,
        reader=reader,
        skeleton=skeleton,
        unit=unit_name,
        scale=scale,
        up_axis=up_axis,
        root_position=root_position,
        swap_sides=swap_sides,
        include=include,
        exclude=exclude,
        holdout=holdout,
        overrides=overrides,
        pattern=pattern,
        templates=tuple(templates.items()),
        joints=tuple(joints[n] for n in JOINT_NAMES),
    )


def load_maps(folder: str | Path) -> list[MocapMap]:
    """All ``*.toml`` maps of a folder, sorted by file name (or one map file); sources must
    be unique."""
    folder = Path(folder)
    files = [folder] if folder.is_file() else sorted(folder.glob("*.toml"))
    if not files:
        what = "no such folder" if not folder.exists() else "no *.toml joint maps found"
        raise MapError(f"{folder}: {what}")
    maps = [load_map(f) for f in files]
    seen: dict[str, str] = {}
    for m in maps:
        if m.source in seen:
            raise MapError(f"{m.path}: source {m.source!r} is also defined by {seen[m.source]}")
        seen[m.source] = m.path
    return maps
