"""A hand-edited ``models/manifest.json`` is served under a version of its content, not
the one it was written with (real copies of the shipped models; an audit, 2026-12-07: a
skeleton scaled 1.5x, a solver's joints reversed, ``serving.passes`` 2 -> 3, all served
other answers under the old ``model``)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from core.manifest import (
    MANIFEST_NAME,
    content_sha256,
    edited_version,
    load_manifest,
    write_manifest,
    written_version,
)

#: The shipped models' version, which the docs quote.
SHIPPED = "mx1-cf785d658788"


def _scale_skeleton(m: dict[str, Any]) -> None:
    sk = m["skeleton"]
    sk["reference_bone_lengths"] = {k: v * 1.5 for k, v in sk["reference_bone_lengths"].items()}


def _reverse_joints(m: dict[str, Any]) -> None:
    entry = next(e for e in m["models"] if e["kind"] == "solver" and len(e["joints"]) > 1)
    entry["joints"] = entry["joints"][::-1]


def _passes(m: dict[str, Any]) -> None:
    m["serving"]["passes"] = 3


def _version(m: dict[str, Any]) -> None:
    m["version"] = "mx1-000000000000"


def test_the_shipped_manifest_records_its_content_and_keeps_its_version(
    models_dir: Path,
) -> None:
    raw = json.loads((models_dir / MANIFEST_NAME).read_text())
    assert raw["content_sha256"] == content_sha256(raw)
    m = load_manifest(models_dir, verify=False)
    assert m.version == raw["version"] == SHIPPED
    assert edited_version(m) is None and written_version(m) is None


@pytest.mark.parametrize(
    "edit",
    [_scale_skeleton, _reverse_joints, _passes, _version],
    ids=["skeleton x1.5", "joints reversed", "passes 3", "version"],
)
def test_a_hand_edit_is_served_under_another_version(
    models_dir: Path, tmp_path: Path, edit: Callable[[dict[str, Any]], None]
) -> None:
    folder = tmp_path / "models"
    shutil.copytree(models_dir, folder)
    raw = json.loads((folder / MANIFEST_NAME).read_text())
    written = raw["version"]
    edit(raw)
    (folder / MANIFEST_NAME).write_text(json.dumps(raw, indent=1))  # (a hand's layout)
    m = load_manifest(folder)  # (the model files verified: still the shipped ones)
    assert m.version != written and m.version.startswith("mx1-") and len(m.version) == 16
    assert edited_version(m) == m.version and written_version(m) == raw["version"]
    again = load_manifest(folder, verify=False)
    assert again.version == m.version  # (one content, one version)


def test_a_layout_change_alone_is_no_edit(models_dir: Path, tmp_path: Path) -> None:
    folder = tmp_path / "models"
    shutil.copytree(models_dir, folder)
    raw = json.loads((folder / MANIFEST_NAME).read_text())
    (folder / MANIFEST_NAME).write_text(json.dumps(dict(reversed(raw.items()))))
    assert load_manifest(folder, verify=False).version == SHIPPED


def test_a_rewritten_manifest_records_its_new_content(models_dir: Path, tmp_path: Path) -> None:
    """What the trainer writes (``write_manifest``: the export, ``pose-trainer serving``,
    the mirror pass) records its content: read back, it is served under its own version."""
    folder = tmp_path / "models"
    shutil.copytree(models_dir, folder)
    m = load_manifest(folder, verify=False)
    serving = m.serving.model_copy(update={"passes": 3})
    write_manifest(folder, m.model_copy(update={"serving": serving, "version": "mx1-abcdefabcdef"}))
    raw = json.loads((folder / MANIFEST_NAME).read_text())
    assert raw["content_sha256"] == content_sha256(raw)
    back = load_manifest(folder, verify=False)
    assert back.version == "mx1-abcdefabcdef" and edited_version(back) is None


def test_an_older_manifest_without_a_content_sha256_is_judged_by_its_version(
    models_dir: Path, tmp_path: Path
) -> None:
    """A manifest written before ``content_sha256``: its serving block edited is told by
    its version (files and serving block, as before), and now served under that."""
    folder = tmp_path / "models"
    shutil.copytree(models_dir, folder)
    raw = json.loads((folder / MANIFEST_NAME).read_text())
    del raw["content_sha256"]
    (folder / MANIFEST_NAME).write_text(json.dumps(raw))
    assert load_manifest(folder, verify=False).version == SHIPPED
    raw["serving"]["passes"] = 3
    (folder / MANIFEST_NAME).write_text(json.dumps(raw))
    m = load_manifest(folder, verify=False)
    assert m.version != SHIPPED and edited_version(m) == m.version
