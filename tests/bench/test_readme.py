"""bench.readme: the README's results are replaced between the markers, and only there."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.readme import END, START, render, splice

REPORT = """# Marionette benchmark report

Generated now by `python -m bench`.

## Goals

| goal | status |
|---|---|
| a | **met** |

## Accuracy (TEST split)

### B2 — completion from key points only

![B2](b2.png)

### Composition ablation

text
"""


def test_render_quotes_the_sections_the_run_has() -> None:
    body = render(REPORT, "reports/")
    assert body.startswith("Generated now by `python -m bench`.")
    assert "#### Goals" in body and "| a | **met** |" in body
    assert "#### B2 — completion from key points only" in body
    assert "](reports/b2.png)" in body  # images relative to the README
    assert "Held-out" not in body  # not in this report: left out, no error
    assert body.rstrip().endswith("[reports/report.md](reports/report.md).")


def test_splice_replaces_only_between_the_markers(tmp_path: Path) -> None:
    readme = f"intro\n{START}\nold results\n{END}\noutro\n"
    out = splice(readme, "new results")
    assert out == f"intro\n{START}\nnew results\n{END}\noutro\n"
    assert splice(out, "new results") == out  # idempotent


@pytest.mark.parametrize(
    "text",
    ["no markers at all", f"{START} only", f"{END} then {START}", f"{START}{END}{START}{END}"],
)
def test_splice_needs_one_pair_of_markers(text: str) -> None:
    with pytest.raises(ValueError, match="bench:start"):
        splice(text, "x")
