"""Where the time of a ``/v1/bvh/solve`` goes, per step, on BVH files of your own:
``python -m bench.bvh_route FILE.bvh [FILE.bvh ...] [--calls 7] [--frame 10]``
``[--frames N] [--wrap K]``.

Each file's edit (its left wrist moved 10 % of the body's height up, soft reach, the
models in ``--models``) runs the route's steps in process, as the route does them (no HTTP):
reading the file (whole, as before 2026-12-04, and only the frame edited, as the route
does now), the character (skeleton, joint map, units, up), the solve, and the answer (the
file with that frame rewritten). Each step's median over ``--calls`` (after one to warm),
in ms of wall time on this host. Units and up axis are inferred (``--units`` to state them).
``--frames N``: each file's frames repeated (or cut) to N, a big file made of a real one;
``--wrap K``: its frames written K values a line, with CRLF line ends and a byte order mark,
as some exporters write them (:func:`reshaped`).
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from core.skeleton import JOINT_INDEX

app = typer.Typer(add_completion=False)


def _median_ms(calls: int, step: Callable[[], Any]) -> tuple[float, Any]:
    times, out = [], None
    for _ in range(calls + 1):
        t0 = time.perf_counter()
        out = step()
        times.append(time.perf_counter() - t0)
    return float(np.median(times[1:])) * 1e3, out


def reshaped(text: str, frames: int | None = None, wrap: int | None = None) -> str:
    """``text`` (a BVH) with its frames repeated or cut to ``frames``, and written ``wrap``
    values a line with CRLF line ends and a byte order mark; None leaves either as it is."""
    if frames is None and wrap is None:
        return text
    at = text.index("Frame Time:")
    end = text.index("\n", at) + 1
    head = text[:at].replace("\r\n", "\n")
    rows = [line for line in text[end:].splitlines() if line.strip()]
    if frames is not None:
        rows = (rows * -(-frames // len(rows)))[:frames]
    head = re.sub(r"Frames:\s*\d+", f"Frames: {len(rows)}", head)
    time_line = text[at:end].rstrip("\r\n")
    if wrap is None:
        return head + time_line + "\n" + "\n".join(rows) + "\n"
    lines = []
    for row in rows:
        words = row.split()
        lines += [" ".join(words[i : i + wrap]) for i in range(0, len(words), wrap)]
    return "\ufeff" + (head + time_line + "\n" + "\n".join(lines) + "\n").replace("\n", "\r\n")


def _row(engine: Any, path: Path, calls: int, frame: int, units: str | None, text: str) -> str:
    """One file's table row (``text``: the file's, as sent)."""
    from service.bvh_models import BVHSolveRequest
    from service.character_bvh import bvh_answer, character_from_bvh, read_request_bvh
    from service.characters import character_problem, solve_character

    target: dict[str, Any] = {"joint": "left_wrist", "position": [0.0, 0.0, 0.0]}
    body: dict[str, Any] = {"bvh": text, "frame": frame, "targets": [target],
                            "options": {"reach": "soft"}}  # fmt: skip
    if units is not None:
        body["units"] = units
    req = BVHSolveRequest.model_validate(body)
    whole, bvh = _median_ms(calls, lambda: read_request_bvh(text))
    one, bvh = _median_ms(calls, lambda: read_request_bvh(text, frame))
    ch = character_from_bvh(bvh, req, req.frame)
    pts = character_problem(ch, req).pose
    wrist = pts[JOINT_INDEX["left_wrist"]].copy()
    wrist[1] += 0.1 * float(pts[:, 1].max() - pts[:, 1].min())
    target["position"] = ch.from_service(wrist[None])[0].tolist()
    req = BVHSolveRequest.model_validate(body)
    made, ch = _median_ms(calls, lambda: character_from_bvh(bvh, req, req.frame))
    solved, edit = _median_ms(calls, lambda: solve_character(engine, ch, req))
    answered, _ = _median_ms(calls, lambda: bvh_answer(bvh, ch, req, edit))
    return (f"| {path.name} | {len(text) / 1e6:.2f} | {bvh.num_frames} | {whole:.1f} | "
            f"{one:.1f} | {made:.1f} | {solved:.1f} | {answered:.1f} |")  # fmt: skip


@app.command()
def main(
    files: list[Path],
    models: Annotated[Path, typer.Option(help="models folder")] = Path("models"),
    calls: Annotated[int, typer.Option(min=1, max=1000)] = 7,
    frame: Annotated[int, typer.Option(min=0)] = 10,
    units: Annotated[str | None, typer.Option(help="units, where not plain from a file")] = None,
    frames: Annotated[
        int | None, typer.Option(min=1, help="each file's frames repeated or cut to this many")
    ] = None,
    wrap: Annotated[
        int | None, typer.Option(min=1, help="frames written this many values a line (CRLF, BOM)")
    ] = None,
) -> None:
    from service.engine import Engine

    engine = Engine(models)
    print("| file | MB | frames | read whole | read the frame | character | solve | answer |")
    print("|---|---|---|---|---|---|---|---|")
    for path in files:
        with path.open(encoding="utf-8", errors="replace", newline="") as f:  # (CRLF as sent)
            text = reshaped(f.read(), frames, wrap)
        print(_row(engine, path, calls, frame, units, text))


if __name__ == "__main__":
    app()
