"""Users' own characters, edited as a user does, scored against what the body really did:
``python -m bench.characters [FILE.bvh ...] [--edits 40] [--on-pelvis] [--serving K=V]``; with
no file, the twelve of :data:`DEFAULT_FILES` taken out of ``--mocap`` (``../shared/mocap``).

Each edit takes two frames of one file 0.2-1 s apart (seeded): the start is frame i as the
file has it (where it was captured: the body may have walked and turned since), the targets
are frame j's own joints (the character's canonical points, the joint map's), and the
answer is scored against frame j, all 21 points, in the character's own skeleton: what
``/v1/bvh/solve`` writes back (its steps in process, as in ``bench.bvh_route``). Beside it
the canonical answer the route laid the character onto (``canonical``: what ``/v1/solve``
would have answered for the same points), FABRIK through the same route (``method:
fabrik``), and the start unchanged. Sets: a lone wrist, both wrists, both ankles, the five
end effectors. MPJPE to frame j and the targets' mean miss, cm; units and up inferred
(``--units`` to state them).
"""

from __future__ import annotations

import subprocess
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

from core.skeleton import JOINT_INDEX, JOINT_NAMES

if TYPE_CHECKING:  # pragma: no cover
    from core.bvh import BVH
    from service.characters import Character

app = typer.Typer(add_completion=False)

#: (name, canonical joints) of each edit set
SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("L wrist", ("left_wrist",)),
    ("L wrist + R wrist", ("left_wrist", "right_wrist")),
    ("L ankle + R ankle", ("left_ankle", "right_ankle")),
    ("5 end eff.", ("head", "left_wrist", "right_wrist", "left_ankle", "right_ankle")),
)
_AD = "animateddrawings_fair_bvh/facebookresearch+AnimatedDrawings@74ee7f0/examples/bvh"
_RI = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7"
_BN = "dataset/Bandai-Namco-Research-Motiondataset-1/data"
#: (archive, member, units to state or None, root_position) of the files scored when none
#: is given: bodies no model was trained on (AnimatedDrawings' child and CMU retarget, five
#: ReActIdle people, whose root channels are a displacement: "add"), then two of the
#: training studios' for reference
DEFAULT_FILES: tuple[tuple[str, str, str | float | None, str], ...] = (
    *[("animateddrawings_fair_bvh.tar.xz", f"{_AD}/fair1/{n}.bvh", "in", "replace")
      for n in ("dab", "jumping", "wave_hello", "zombie")],
    ("animateddrawings_fair_bvh.tar.xz", f"{_AD}/cmu1/jumping_jacks.bvh", 0.0564444, "replace"),
    *[("reactidle_bvh.tar.xz", f"{_RI}/{n}.bvh", None, "add")
      for n in ("acted/001_acted", "acted/002_acted", "acted/008_acted",
                "genuine/003_genuine", "genuine/011_genuine")],
    ("bandai-namco-research-motiondataset.tar.xz", f"{_BN}/dataset-1_walk_normal_001.bvh", None,
     "replace"),
    ("cmu-dance.tar.xz", "train_data_bvh/salsa/01.bvh", None, "replace"),
)  # fmt: skip
#: (column, options of the request)
METHODS: tuple[tuple[str, dict[str, str]], ...] = (
    ("FABRIK", {"method": "fabrik", "reach": "exact"}),
    ("soft", {"reach": "soft"}),
    ("exact", {"reach": "exact"}),
)


@dataclass(frozen=True)
class Scores:
    """Per method (``start``, ``FABRIK``, ``soft``, ``exact`` and the canonical answers
    ``soft canonical``, ``exact canonical``): MPJPE to the real frame and mean target
    miss, cm, one entry per edit."""

    mpjpe: dict[str, list[float]]
    reach: dict[str, list[float]]


def frame_pairs(frames: int, fps: float, n: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """``n`` (i, j) frame pairs of a clip, j 0.2-1 s after i (fewer where it is short)."""
    lo, hi = max(1, round(0.2 * fps)), max(1, round(1.0 * fps))
    if frames <= lo:
        return []
    out = []
    for _ in range(n):
        gap = int(rng.integers(lo, min(hi, frames - 1) + 1))
        i = int(rng.integers(0, frames - gap))
        out.append((i, i + gap))
    return out


def score_file(
    engine: Any,
    path: Path,
    edits: int,
    seed: int,
    units: str | float | None = None,
    on_pelvis: bool = False,
    root_position: str = "replace",
) -> dict[str, Scores]:
    """Every set's scores on one file (see the module docstring)."""
    from core.retarget import canonical_points
    from service.bvh_models import BVHSolveRequest
    from service.character_bvh import read_request_bvh
    from service.characters import character_problem, solve_prepared

    text = path.read_text(encoding="utf-8", errors="replace")
    bvh = read_request_bvh(text)
    pairs = frame_pairs(bvh.num_frames, 1.0 / bvh.frame_time, edits, np.random.default_rng(seed))
    out: dict[str, Scores] = {name: Scores({}, {}) for name, _ in SETS} if pairs else {}
    for i, j in pairs:  # the character and the real frame once per pair, every set on them
        ch, base = file_character(bvh, text, i, units, root_position)
        here = canonical_points(ch.skel, ch.pose, ch.jmap)
        real = frame_points(ch, bvh, j, root_position)
        if on_pelvis:  # frame j moved so its pelvis is the start's (no travel between)
            real = real - real[JOINT_INDEX["pelvis"]] + here[JOINT_INDEX["pelvis"]]
        truth = ch.to_service(real)
        label = ch.jmap.describe()
        for name, joints in SETS:
            scores, idx = out[name], [JOINT_INDEX[n] for n in joints]
            targets = [{"joint": label[JOINT_NAMES[k]], "position": real[k].tolist()} for k in idx]
            _add(scores, "start", ch.to_service(here), truth, idx)
            for column, options in METHODS:
                req = BVHSolveRequest.model_validate({**base, "targets": targets,
                                                      "options": options})  # fmt: skip
                edit = solve_prepared(engine, ch, character_problem(ch, req))
                got = ch.to_service(canonical_points(ch.skel, edit.pose, ch.jmap))
                _add(scores, column, got, truth, idx)
                if column != "FABRIK":
                    _add(scores, f"{column} canonical", np.asarray(edit.result.pose), truth, idx)
    return out


@contextmanager
def unreadable(path: Path) -> Iterator[None]:
    """A file the BVH route refuses (not BVH, a joint map not found, ...) as the command
    line's one-line error naming it."""
    from service.errors import PoseError

    try:
        yield
    except PoseError as exc:
        raise typer.BadParameter(f"{path}: {exc}", param_hint="FILES") from None


def file_character(
    bvh: BVH, text: str, frame: int, units: str | float | None, root_position: str
) -> tuple[Character, dict[str, Any]]:
    """The character of ``frame`` of a file (``bvh``, parsed from ``text``) as
    ``/v1/bvh/solve`` reads it (:func:`read_as`), and the request fields that read it so
    (their one target a placeholder)."""
    from service.bvh_models import BVHSolveRequest
    from service.character_bvh import character_from_bvh

    head = {"joint": "head", "position": [0.0, 0.0, 0.0]}  # (the character alone)
    base = {"bvh": text, "frame": frame, "targets": [head], **read_as(units, root_position)}
    return character_from_bvh(bvh, BVHSolveRequest.model_validate(base), frame), base


def frame_points(ch: Character, bvh: BVH, frame: int, root_position: str) -> np.ndarray:
    """Frame ``frame``'s canonical points on the skeleton of ``ch`` (:func:`file_character`),
    in the file's units and axes."""
    from core.bvh_write import pose_of
    from core.retarget import canonical_points

    pose = pose_of(bvh, frame, root_add=root_position == "add")
    return np.asarray(canonical_points(ch.skel, pose, ch.jmap))


def read_as(units: str | float | None, root_position: str) -> dict[str, Any]:
    """The request fields that say how a file is read, where they are not the defaults."""
    out: dict[str, Any] = {} if units is None else {"units": units}
    if root_position != "replace":
        out["root_position"] = root_position
    return out


def _add(scores: Scores, method: str, pose: np.ndarray, truth: np.ndarray, idx: list[int]) -> None:
    err = np.linalg.norm(np.asarray(pose, dtype=np.float64) - truth, axis=1) * 100.0
    scores.mpjpe.setdefault(method, []).append(float(err.mean()))
    scores.reach.setdefault(method, []).append(float(err[idx].mean()))


COLUMNS = ("start", "FABRIK", "soft", "exact", "soft canonical", "exact canonical")


def table(rows: Sequence[tuple[str, str, Scores]]) -> list[str]:
    """Markdown lines: one row per (file, set), MPJPE per method, then the reach."""
    head = ["file", "set", "edits", *COLUMNS, "reach soft / exact"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for file, name, s in rows:
        n = len(s.mpjpe["start"])
        cells = [f"{np.mean(s.mpjpe[m]):.2f}" for m in COLUMNS]
        reach = f"{np.mean(s.reach['soft']):.2f} / {np.mean(s.reach['exact']):.3f}"
        lines.append("| " + " | ".join([file, name, str(n), *cells, reach]) + " |")
    return lines


#: The training studios' archives among :data:`DEFAULT_FILES` (scored for reference).
IN_STUDIO = ("bandai-namco-research-motiondataset.tar.xz", "cmu-dance.tar.xz")


def summary(rows: Sequence[tuple[str, str, str, Scores]]) -> list[str]:
    """Markdown lines: per group of files (``rows``: group, file, set, scores), each set and
    then every set, the mean over the rows of each method's MPJPE (each row a mean over its
    edits), and the rows where exact reach is below FABRIK."""
    head = ["files", "set", "rows", *COLUMNS, "exact < FABRIK"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for group in dict.fromkeys(g for g, _, _, _ in rows):
        mine = [(name, s) for g, _, name, s in rows if g == group]
        files = len({f for g, f, _, _ in rows if g == group})
        for name in [*dict.fromkeys(n for n, _ in mine), "all sets"]:
            some = [s for n, s in mine if name in (n, "all sets")]
            means = {m: [float(np.mean(s.mpjpe[m])) for s in some] for m in COLUMNS}
            below = sum(e < f for e, f in zip(means["exact"], means["FABRIK"], strict=True))
            cells = [f"{np.mean(means[m]):.3f}" for m in COLUMNS]
            label = f"{files} {group}"
            lines.append(
                "| " + " | ".join([label, name, str(len(some)), *cells, f"{below}/{len(some)}"])
                + " |"
            )  # fmt: skip
    return lines


def extract(mocap: Path, out: Path) -> list[tuple[Path, str | float | None, str]]:
    """:data:`DEFAULT_FILES` out of their archives in ``mocap`` into ``out`` (GNU tar)."""
    by_archive: dict[str, list[str]] = {}
    for archive, member, _, _ in DEFAULT_FILES:
        by_archive.setdefault(archive, []).append(member)
    for archive, members in by_archive.items():
        subprocess.run(["tar", "-xJf", str(mocap / archive), "-C", str(out), *members],
                       check=True)  # fmt: skip
    return [(out / member, units, root) for _, member, units, root in DEFAULT_FILES]


#: The command line's options shared with bench.clips: files given, else the default files
#: out of the archives in ``mocap``; the models; serving settings instead of the manifest's.
Files = Annotated[list[Path] | None, typer.Argument(exists=True, dir_okay=False, readable=True)]
Mocap = Annotated[Path, typer.Option(help="archives of the default files")]
Models = Annotated[Path, typer.Option(help="models folder")]
Serving = Annotated[
    list[str] | None,
    typer.Option(metavar="KEY=VALUE", help="a serving setting instead (bench.heldout's)"),
]


@app.command()
def main(
    files: Files = None,
    mocap: Mocap = Path("../shared/mocap"),
    models: Models = Path("models"),
    edits: Annotated[int, typer.Option(min=1, max=10_000, help="edits per file and set")] = 40,
    seed: Annotated[int, typer.Option(help="seed of the frame pairs")] = 0,
    units: Annotated[str | None, typer.Option(help="units, where not plain from a file")] = None,
    on_pelvis: Annotated[
        bool, typer.Option(help="frame j moved onto the start's pelvis (no travel)")
    ] = False,
    root_position: Annotated[
        str, typer.Option(help="the files' root channels: replace (BVH) or add (a displacement)")
    ] = "replace",
    serving: Serving = None,
) -> None:
    from bench.heldout import engine_for

    engine = engine_for(models, serving)
    given: str | float | None = units
    if units is not None and units.replace(".", "", 1).isdigit():
        given = float(units)  # metres per unit
    rows: list[tuple[str, str, str, Scores]] = []
    with tempfile.TemporaryDirectory() as tmp:
        if files:
            todo = [(p, given, root_position, "given") for p in files]
        else:
            groups = ["in-studio" if a in IN_STUDIO else "held-out" for a, *_ in DEFAULT_FILES]
            todo = [(*f, g) for f, g in zip(extract(mocap, Path(tmp)), groups, strict=True)]
        for path, stated, root, group in todo:
            with unreadable(path):
                scored = score_file(engine, path, edits, seed, stated, on_pelvis, root)
            rows.extend((group, path.name, name, scores) for name, scores in scored.items())
    mode = " --on-pelvis" if on_pelvis else ""
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    print(f"Written by `python -m bench.characters{mode}` ({when}, models {engine.version}).\n")
    print("\n".join(table([(f, n, s) for _, f, n, s in rows])))
    print("\nMean over the rows (MPJPE, cm):\n")
    print("\n".join(summary(rows)))


if __name__ == "__main__":
    app()
