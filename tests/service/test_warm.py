"""Every kernel a user's request runs is compiled at start: after the service's warm-up,
no request of any kind (the docs' examples; single edits soft, exact, FABRIK, with pins,
passes, carry, on one joint, the pelvis, a pair, five targets; the item-list and columnar
batches) compiles a kernel for argument types the warm-up did not use. A kernel compiled
on a request stalls it for seconds (about 22 s on this machine for the six a read-only
per-item array once asked for) on the first such request after a deploy, whose image
holds only the warm-up's kernels. Run in a fresh process (``tests/service/warm_probe.py``)
so that no other test's calls count."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

from tests.conftest import REPO_ROOT


def test_no_request_compiles_a_kernel(models_dir: Path) -> None:
    out = subprocess.run(
        [sys.executable, "-m", "tests.service.warm_probe", str(models_dir)],
        cwd=REPO_ROOT, env=dict(os.environ), capture_output=True, text=True, timeout=600,
        check=True,
    )  # fmt: skip
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert len(got["statuses"]) > 60
    assert set(got["statuses"]) == {200}, got["statuses"]
    assert got["added"] == {}, got["added"]
