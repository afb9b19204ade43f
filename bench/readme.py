"""Copy the benchmark report's headline tables into README.md (between markers).

``python -m bench.readme [--report reports/report.md] [--readme README.md]``; `make bench`
runs it, so the README's results always come from the last measured run."""

from __future__ import annotations

import argparse
import re
from pathlib import Path

START, END = "<!-- results:start -->", "<!-- results:end -->"
#: Report sections quoted in the README (by heading), in this order.
SECTIONS = (
    "## Goals",
    "### B2 — completion from key points only",
    "### Composition ablation",
    "### In-process latency (one thread)",
    "### HTTP (uvicorn on loopback)",
    "## Model size on disk",
)


def section(report: str, heading: str) -> str:
    """The text under ``heading`` up to the next heading of the same or higher level."""
    level = heading.split(" ")[0]
    start = report.index(heading + "\n")
    pattern = re.compile(rf"^#{{1,{len(level)}}} ", re.M)
    nxt = pattern.search(report, start + len(heading) + 1)
    return report[start : nxt.start() if nxt else len(report)].strip()


def render(report: str, prefix: str) -> str:
    header = report.splitlines()[2]  # "Generated ... by `python -m bench ...`"
    parts = [header, ""]
    for heading in SECTIONS:
        text = section(report, heading)
        text = re.sub(r"^#+ ", "#### ", text, count=1)
        # images in the report are relative to reports/
        text = re.sub(r"\]\((?!http)([^)]+\.png)\)", rf"]({prefix}\1)", text)
        parts += [text, ""]
    link = f"{prefix}report.md"
    parts.append(f"The whole report, with every table and plot: [{link}]({link}).")
    return "\n".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--report", type=Path, default=Path("reports/report.md"))
    parser.add_argument("--readme", type=Path, default=Path("README.md"))
    args = parser.parse_args()
    readme = args.readme.read_text(encoding="utf-8")
    if START not in readme or END not in readme:
        raise SystemExit(f"{args.readme}: markers {START} / {END} not found")
    prefix = args.report.parent.as_posix().rstrip("/") + "/"
    body = render(args.report.read_text(encoding="utf-8"), prefix)
    head, rest = readme.split(START, 1)
    _, tail = rest.split(END, 1)
    args.readme.write_text(f"{head}{START}\n{body}\n{END}{tail}", encoding="utf-8")
    print(f"updated {args.readme} from {args.report}")


if __name__ == "__main__":
    main()
