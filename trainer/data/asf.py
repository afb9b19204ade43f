"""Acclaim ASF (skeleton) / AMC (motion) reader with batched forward kinematics (numpy only).

The object :func:`read_amc` returns has the interface the dataset builder uses for BVH
(:class:`core.bvh.BVH`): ``name``, ``joint_names``, ``num_frames``, ``fps``, ``index`` and
``forward_kinematics(names, frames=...)`` giving world positions ``[F, K, 3]`` in file units.

Conventions (Acclaim, as the CMU database uses them; checked against rendered CMU poses):

- Units: the ASF ``:units`` block gives ``length`` (CMU: 0.45, meaning file values are
  inches x 0.45, so metres = value x 0.0254 / length: :attr:`ASFSkeleton.metres_per_unit`)
  and ``angle`` (``deg`` or ``rad``; an AMC ``:RADIANS`` / ``:DEGREES`` line overrides it).
- A bone's ``axis ax ay az XYZ`` line gives its local frame C in world (rest) coordinates;
  ``direction`` (world, rest) and ``length`` give the bone vector. Rotations are composed
  in the listed axis order with the first axis applied first: ``XYZ`` means
  ``C = Rz(az) @ Ry(ay) @ Rx(ax)``. The AMC values of a bone follow its ``dof`` line and are
  composed the same way (``dof rx ry rz``: ``M = Rz @ Ry @ Rx``); the root's follow the
  ``:root order`` line (``TX TY TZ RX RY RZ``) and its ``axis`` / ``orientation``.
- Global rotation ``G = G_parent @ C @ M @ C^-1`` (the root: ``C_root @ M @ C_root^-1``) and
  the bone's END is ``end_parent + G @ direction * length``; the root sits at its AMC
  translation (the ASF root ``position`` is the rest value, replaced by the motion).
- Joint names are ``root`` (the root position) and the bone names, each standing for the
  bone's END (``lfemur`` = the knee). A bone starts where its parent ends.
- AMC files carry no frame rate: the reader is told it (CMU captured at 120 Hz).

Malformed input raises :class:`ASFError` naming the file, the line and the reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from core.euler import axis_rotations
from core.io import FileError

FloatArray = npt.NDArray[np.float64]

#: CMU's capture rate; AMC files do not state one.
CMU_FPS = 120.0
_ROT_DOFS = {"rx": "X", "ry": "Y", "rz": "Z"}
_ROOT_CHANNELS = {"tx", "ty", "tz", "rx", "ry", "rz"}


class ASFError(FileError):
    """A malformed or unsupported ASF/AMC file; names the file and the reason."""


@dataclass(frozen=True)
class ASFBone:
    """One bone of an ASF skeleton (index 0 of :attr:`ASFSkeleton.bones` is the root)."""

    name: str
    parent: int  # index into ASFSkeleton.bones, -1 for the root
    direction: tuple[float, float, float]  # unit vector, world rest frame
    length: float  # file length units
    axis: tuple[float, float, float]  # angles of the local frame, file angle units
    axis_order: str  # e.g. "XYZ": the first listed axis is applied first
    dof: tuple[str, ...] = ()  # AMC channels in file order, e.g. ("rx", "ry", "rz")


@dataclass(frozen=True)
class ASFSkeleton:
    """A parsed ASF file: bones in topological order (parents first), root first."""

    name: str
    bones: tuple[ASFBone, ...]
    length_unit: float  # the ``:units length`` value (CMU: 0.45)
    angle_unit: str  # "deg" or "rad"
    root_order: tuple[str, ...]  # AMC root channels, e.g. ("tx", "ty", "tz", "rx", "ry", "rz")
    _index: dict[str, int] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        self._index.update({b.name: i for i, b in enumerate(self.bones)})

    @property
    def metres_per_unit(self) -> float:
        """Metres per file length unit: values are inches x ``length`` (CMU: 0.0254 / 0.45)."""
        return 0.0254 / self.length_unit

    @property
    def joint_names(self) -> tuple[str, ...]:
        return tuple(b.name for b in self.bones)

    def index(self, name: str) -> int:
        try:
            return self._index[name]
        except KeyError:
            raise KeyError(
                f"{self.name}: no bone {name!r}; bones are {', '.join(self.joint_names)}"
            ) from None

    def bone_lengths(self) -> dict[str, float]:
        """Length of every bone (file units), by name (the root has 0)."""
        return {b.name: b.length for b in self.bones}


def _rotation(order: str, angles: FloatArray) -> FloatArray:
    """``[..., 3, 3]`` rotations; ``angles[..., k]`` (radians) about axis ``order[k]``, the
    first axis applied first: ``R = R_order[-1] @ ... @ R_order[0]``."""
    out = np.broadcast_to(np.eye(3), (*angles.shape[:-1], 3, 3)).copy()
    for k, axis in enumerate(order):
        out = np.matmul(axis_rotations(axis, angles[..., k]), out)
    return out


# --------------------------------------------------------------------------- ASF


def _floats(file: str, lineno: int, words: Sequence[str], n: int, what: str) -> list[float]:
    if len(words) < n:
        raise ASFError(file, f"line {lineno}: {what} needs {n} numbers, got {len(words)}")
    try:
        return [float(w) for w in words[:n]]
    except ValueError:
        raise ASFError(file, f"line {lineno}: {what}: not a number in {list(words)}") from None


def _axis_order(file: str, lineno: int, word: str) -> str:
    order = word.upper()
    if not order or any(c not in "XYZ" for c in order):
        raise ASFError(file, f"line {lineno}: bad axis order {word!r}")
    return order


def parse_asf(text: str, name: str = "<string>") -> ASFSkeleton:
    """Parse ASF text; ``name`` is used in error messages."""
    lines = [(i, ln.split("#", 1)[0].split()) for i, ln in enumerate(text.splitlines(), start=1)]
    lines = [(i, w) for i, w in lines if w]
    if not any(w[0].startswith(":") for _, w in lines):
        raise ASFError(name, "not an ASF file (no ':' sections)")
    length_unit, angle_unit = 1.0, "deg"
    root_order: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
    root_axis_order, root_orient = "XYZ", (0.0, 0.0, 0.0)
    raw: list[dict[str, object]] = []
    children: dict[str, list[str]] = {}
    section = ""
    current: dict[str, object] | None = None
    for lineno, words in lines:
        head = words[0]
        if head.startswith(":"):
            section = head.lower()
            continue
        key = head.lower()
        if section == ":units":
            if key == "length":
                length_unit = _floats(name, lineno, words[1:], 1, "length unit")[0]
                if length_unit <= 0:
                    raise ASFError(name, f"line {lineno}: length unit must be > 0")
            elif key == "angle":
                angle_unit = words[1].lower() if len(words) > 1 else ""
                if angle_unit not in ("deg", "rad"):
                    raise ASFError(name, f"line {lineno}: angle unit must be deg or rad")
        elif section == ":root":
            if key == "order":
                root_order = tuple(w.lower() for w in words[1:])
                bad = [w for w in root_order if w not in _ROOT_CHANNELS]
                if bad or len(set(root_order)) != len(root_order):
                    raise ASFError(name, f"line {lineno}: bad root order {words[1:]}")
            elif key == "axis":
                root_axis_order = _axis_order(name, lineno, words[1] if len(words) > 1 else "")
            elif key == "orientation":
                o = _floats(name, lineno, words[1:], 3, "root orientation")
                root_orient = (o[0], o[1], o[2])
        elif section == ":bonedata":
            if key == "begin":
                current = {"line": lineno}
            elif key == "end":
                if current is None:
                    raise ASFError(name, f"line {lineno}: 'end' without 'begin'")
                raw.append(current)
                current = None
            elif current is None:
                raise ASFError(name, f"line {lineno}: {head!r} outside a begin/end block")
            elif key == "name":
                current["name"] = words[1] if len(words) > 1 else ""
            elif key == "direction":
                current["direction"] = _floats(name, lineno, words[1:], 3, "direction")
            elif key == "length":
                current["length"] = _floats(name, lineno, words[1:], 1, "length")[0]
            elif key == "axis":
                current["axis"] = _floats(name, lineno, words[1:], 3, "axis")
                current["axis_order"] = _axis_order(
                    name, lineno, words[4] if len(words) > 4 else ""
                )
            elif key == "dof":
                dof = tuple(w.lower() for w in words[1:])
                bad = [w for w in dof if w not in _ROT_DOFS]
                if bad:
                    raise ASFError(
                        name, f"line {lineno}: unsupported dof {bad} (only rx, ry, rz are read)"
                    )
                current["dof"] = dof
        elif section == ":hierarchy":
            if key in ("begin", "end"):
                continue
            children.setdefault(head, []).extend(words[1:])
    if current is not None:
        raise ASFError(name, f"bone block of line {current['line']} has no 'end'")
    if not raw:
        raise ASFError(name, "no :bonedata bones")

    data: dict[str, dict[str, object]] = {}
    for item in raw:
        bone = str(item.get("name", ""))
        for k in ("name", "direction", "length", "axis"):
            if k not in item:
                raise ASFError(name, f"bone block of line {item['line']} has no {k!r}")
        if bone in data or bone == "root":
            raise ASFError(name, f"line {item['line']}: duplicate bone name {bone!r}")
        data[bone] = item
    for parent, kids in children.items():
        for kid in [parent, *kids]:
            if kid != "root" and kid not in data:
                raise ASFError(name, f":hierarchy names an unknown bone {kid!r}")

    bones: list[ASFBone] = [
        ASFBone("root", -1, (0.0, 0.0, 0.0), 0.0, root_orient, root_axis_order, ())
    ]
    placed = {"root": 0}
    queue = ["root"]
    while queue:
        parent = queue.pop(0)
        for kid in children.get(parent, []):
            if kid in placed:
                raise ASFError(name, f":hierarchy gives bone {kid!r} two parents (or a cycle)")
            item = data[kid]
            d = np.asarray(item["direction"], dtype=np.float64)
            norm = float(np.linalg.norm(d))
            length = float(item["length"])  # type: ignore[arg-type]
            if norm == 0.0 and length != 0.0:
                raise ASFError(name, f"line {item['line']}: bone {kid!r} has a zero direction")
            unit = d / norm if norm > 0 else d
            ax = item["axis"]
            assert isinstance(ax, list)
            placed[kid] = len(bones)
            bones.append(
                ASFBone(
                    kid,
                    placed[parent],
                    (float(unit[0]), float(unit[1]), float(unit[2])),
                    length,
                    (float(ax[0]), float(ax[1]), float(ax[2])),
                    str(item["axis_order"]),
                    tuple(item.get("dof", ())),  # type: ignore[arg-type]
                )
            )
            queue.append(kid)
    orphans = sorted(set(data) - set(placed))
    if orphans:
        raise ASFError(name, f"bones not reachable from the root in :hierarchy: {orphans}")
    return ASFSkeleton(
        name=name,
        bones=tuple(bones),
        length_unit=length_unit,
        angle_unit=angle_unit,
        root_order=root_order,
    )


def read_asf(path: str | Path, name: str | None = None) -> ASFSkeleton:
    path = Path(path)
    label = name if name is not None else str(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ASFError(label, f"cannot read: {exc.strerror or exc}") from None
    return parse_asf(text, label)


# --------------------------------------------------------------------------- AMC


@dataclass(frozen=True)
class AMC:
    """A parsed AMC motion on its skeleton (same interface as :class:`core.bvh.BVH` for the
    dataset builder)."""

    name: str
    skeleton: ASFSkeleton
    frame_numbers: npt.NDArray[np.int64]  # as written in the file
    channels: dict[str, FloatArray]  # per bone with dofs (and "root"): [F, n_dof] file values
    angle_unit: str  # "deg" or "rad" (the AMC's own line, else the ASF's)
    fps: float = CMU_FPS

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.skeleton.joint_names

    @property
    def num_frames(self) -> int:
        return int(self.frame_numbers.shape[0])

    def index(self, name: str) -> int:
        return self.skeleton.index(name)

    def forward_kinematics(
        self,
        names: Sequence[str] | None = None,
        frames: slice | npt.NDArray[np.integer] | None = None,
    ) -> FloatArray:
        """World positions ``[F, K, 3]`` (file length units) of ``names`` (default: all):
        ``root`` is the root position, any other name the END of that bone. ``frames``
        selects frames before FK; only the requested bones' ancestors are evaluated."""
        sk = self.skeleton
        wanted = list(range(len(sk.bones))) if names is None else [sk.index(n) for n in names]
        sel = slice(None) if frames is None else frames
        n_frames = int(np.arange(self.num_frames)[sel].shape[0])
        to_rad = np.pi / 180.0 if self.angle_unit == "deg" else 1.0
        axis_rad = np.pi / 180.0 if sk.angle_unit == "deg" else 1.0

        needed: set[int] = set()
        for j in wanted:
            while j >= 0 and j not in needed:
                needed.add(j)
                j = sk.bones[j].parent

        glob_rot: dict[int, FloatArray] = {}
        glob_pos: dict[int, FloatArray] = {}
        for j in sorted(needed):  # topological: parents precede children
            bone = sk.bones[j]
            c = _rotation(bone.axis_order, np.asarray(bone.axis) * axis_rad)
            if j == 0:
                values = self.channels["root"][sel]
                order = sk.root_order
                trans = np.zeros((n_frames, 3))
                for k, ch in enumerate(order):
                    if ch[0] == "t":
                        trans[:, "xyz".index(ch[1])] = values[:, k]
                rot_cols = [k for k, ch in enumerate(order) if ch[0] == "r"]
                seq = "".join(order[k][1].upper() for k in rot_cols)
                m = _rotation(seq, values[:, rot_cols] * to_rad)
                glob_rot[j] = np.asarray(c @ m @ c.T)
                glob_pos[j] = trans
                continue
            prot = glob_rot[bone.parent]
            if bone.dof:
                seq = "".join(_ROT_DOFS[d] for d in bone.dof)
                m = _rotation(seq, self.channels[bone.name][sel] * to_rad)
                glob_rot[j] = np.asarray(prot @ (c @ m @ c.T))
            else:
                glob_rot[j] = prot
            vec = np.asarray(bone.direction) * bone.length
            glob_pos[j] = glob_pos[bone.parent] + np.einsum("fij,j->fi", glob_rot[j], vec)

        out = np.empty((n_frames, len(wanted), 3), dtype=np.float64)
        for k, j in enumerate(wanted):
            out[:, k] = glob_pos[j]
        return out


def parse_amc(
    text: str, skeleton: ASFSkeleton, name: str = "<string>", fps: float = CMU_FPS
) -> AMC:
    """Parse AMC text against its ASF skeleton (every frame must give every bone with dofs,
    with exactly as many values as the bone's ``dof`` line)."""
    if not (np.isfinite(fps) and fps > 0):
        raise ASFError(name, f"bad frame rate {fps}")
    sizes = {b.name: len(b.dof) for b in skeleton.bones[1:] if b.dof}
    sizes["root"] = len(skeleton.root_order)
    angle_unit = skeleton.angle_unit
    frame_numbers: list[int] = []
    rows: dict[str, list[list[float]]] = {b: [] for b in sizes}
    seen: set[str] = set()

    def close_frame(lineno: int) -> None:
        if frame_numbers and seen != set(sizes):
            missing = sorted(set(sizes) - seen)
            raise ASFError(
                name, f"line {lineno}: frame {frame_numbers[-1]} lacks bones {missing[:5]}"
            )

    for lineno, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if not words or words[0].startswith("#"):
            continue
        head = words[0]
        if head.startswith(":"):
            flag = head.upper()
            if flag == ":RADIANS":
                angle_unit = "rad"
            elif flag == ":DEGREES":
                angle_unit = "deg"
            continue
        if len(words) == 1 and head.lstrip("-").isdigit():
            close_frame(lineno)
            frame_numbers.append(int(head))
            seen = set()
            continue
        if not frame_numbers:
            raise ASFError(name, f"line {lineno}: {head!r} before the first frame number")
        if head not in sizes:
            if head in skeleton._index:  # a bone without dofs must not carry values
                raise ASFError(name, f"line {lineno}: bone {head!r} has no dof in the ASF")
            raise ASFError(name, f"line {lineno}: unknown bone {head!r}")
        if head in seen:
            raise ASFError(name, f"line {lineno}: bone {head!r} twice in one frame")
        if len(words) - 1 != sizes[head]:
            raise ASFError(
                name,
                f"line {lineno}: bone {head!r} needs {sizes[head]} values, got {len(words) - 1}",
            )
        try:
            rows[head].append([float(w) for w in words[1:]])
        except ValueError:
            raise ASFError(name, f"line {lineno}: not a number in {words[1:]}") from None
        seen.add(head)
    close_frame(len(text.splitlines()) + 1)
    if not frame_numbers:
        raise ASFError(name, "no frames (not an AMC file?)")
    return AMC(
        name=name,
        skeleton=skeleton,
        frame_numbers=np.asarray(frame_numbers, dtype=np.int64),
        channels={
            b: np.asarray(v, dtype=np.float64).reshape(-1, sizes[b]) for b, v in rows.items()
        },
        angle_unit=angle_unit,
        fps=float(fps),
    )


def read_amc(
    path: str | Path, skeleton: ASFSkeleton, name: str | None = None, fps: float = CMU_FPS
) -> AMC:
    """Read an AMC file on its skeleton (``ASFError`` on malformed content)."""
    path = Path(path)
    label = name if name is not None else str(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ASFError(label, f"cannot read: {exc.strerror or exc}") from None
    return parse_amc(text, skeleton, label, fps)
