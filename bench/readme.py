"""Copy the benchmark report's headline tables into README.md, between the markers
``<!-- bench:start -->`` and ``<!-- bench:end -->`` (everything between them is replaced).

``python -m bench.readme [--report reports/report.md] [--readme README.md]``; `make bench`
runs it, so the README's results always come from the last measured run."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated

import typer

START, END = "<!-- bench:start -->", "<!-- bench:end -->"
#: Report sections quoted in the README (by heading), in this order; a section the run
#: did not measure is left out.
SECTIONS = (
    "## Goals",
    "### Goals on held-out bodies (issue 11)",
    "### Held-out bodies beside the in-studio test split",
    "### The same edits, starts where they were captured",
    "### B2 — completion from key points only",
    "### Composition ablation",
    "### In-process latency (one thread)",
    "### HTTP (uvicorn on loopback)",
    "## Model size on disk",
)


def section(report: str, heading: str) -> str | None:
    """The text under ``heading`` up to the next heading of the same or higher level."""
    level = heading.split(" ")[0]
    start = report.find(heading + "\n")
    if start < 0:
        return None
    pattern = re.compile(rf"^#{{1,{len(level)}}} ", re.M)
    nxt = pattern.search(report, start + len(heading) + 1)
    return report[start : nxt.start() if nxt else len(report)].strip()


def render(report: str, prefix: str) -> str:
    header = report.splitlines()[2]  # "Generated ... by `python -m bench ...`"
    parts = [header, ""]
    for heading in SECTIONS:
        text = section(report, heading)
        if text is None:
            continue
        text = re.sub(r"^#+ ", "#### ", text, count=1)
        # images in the report are relative to reports/
        text = re.sub(r"\]\((?!http)([^)]+\.png)\)", rf"]({prefix}\1)", text)
        parts += [text, ""]
    link = f"{prefix}report.md"
    parts.append(f"The whole report, with every table and plot: [{link}]({link}).")
    return "\n".join(parts)


def splice(readme: str, body: str, where: str = "README") -> str:
    """``readme`` with the text between the markers replaced by ``body``."""
    if (
        readme.count(START) != 1
        or readme.count(END) != 1
        or readme.index(START) > readme.index(END)
    ):
        raise ValueError(f"{where}: expected one {START} followed by one {END}")
    head, rest = readme.split(START, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{START}\n{body}\n{END}{tail}"


def main(
    report: Annotated[Path, typer.Option(help="The benchmark report.")] = Path("reports/report.md"),
    readme: Annotated[Path, typer.Option(help="The README to update.")] = Path("README.md"),
) -> None:
    """Copy the report's headline tables into the README between the markers."""
    for path, hint in ((report, "--report"), (readme, "--readme")):
        if not path.is_file():
            raise typer.BadParameter(f"no such file: {path}", param_hint=hint)
    text = readme.read_text(encoding="utf-8")
    prefix = report.parent.as_posix().rstrip("/") + "/"
    body = render(report.read_text(encoding="utf-8"), prefix)
    try:
        updated = splice(text, body, str(readme))
    except ValueError as exc:
        raise typer.BadParameter(str(exc), param_hint="--readme") from None
    readme.write_text(updated, encoding="utf-8")
    typer.echo(f"updated {readme} from {report}")


if __name__ == "__main__":
    typer.run(main)
