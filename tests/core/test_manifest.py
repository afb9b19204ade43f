"""``core.manifest.ManifestError`` as a caller in another process gets it: the errors of
loading a real manifest, cut short or naming a file that is not there, pickled and read
back whole."""

from __future__ import annotations

import pickle
import shutil
from pathlib import Path

import pytest

from core.manifest import MANIFEST_NAME, ManifestError, load_manifest


def test_a_manifest_error_survives_pickling(models_dir: Path, tmp_path: Path) -> None:
    """``ManifestError(path, reason)`` passed ``args`` its one message: unpickling it was
    ``TypeError: missing 1 required positional argument: 'reason'``."""
    shutil.copy(models_dir / MANIFEST_NAME, tmp_path / MANIFEST_NAME)  # (its models not)
    text = (models_dir / MANIFEST_NAME).read_text()
    cut = tmp_path / "cut"
    cut.mkdir()
    (cut / MANIFEST_NAME).write_text(text[: len(text) // 2])
    errors = []
    for folder, reason in ((tmp_path, "model file missing"), (cut, "not readable JSON")):
        with pytest.raises(ManifestError) as info:
            load_manifest(folder)
        assert info.value.reason.startswith(reason), info.value
        errors.append(info.value)
    for err in errors:
        back = pickle.loads(pickle.dumps(err))
        assert type(back) is ManifestError and str(back) == str(err) and back.args == err.args
        assert (back.path, back.reason) == (err.path, err.reason) and vars(back) == vars(err)


def test_a_file_that_is_not_the_manifest_s_names_both_hashes(
    models_dir: Path, tmp_path: Path
) -> None:
    """A model file of the right size but other bytes is refused with its own sha256 and
    the manifest's (an ops audit, 2026-12-07: only the file's was shown)."""
    import hashlib
    import shutil

    copy = tmp_path / "models"
    shutil.copytree(models_dir, copy)
    entry = load_manifest(copy, verify=False).models[0]
    data = bytearray((copy / entry.file).read_bytes())
    data[-1] ^= 0xFF
    (copy / entry.file).write_bytes(bytes(data))
    with pytest.raises(ManifestError) as err:
        load_manifest(copy)
    own = hashlib.sha256(bytes(data)).hexdigest()
    assert (
        err.value.reason == f"sha256 {own[:12]}… does not match the manifest's {entry.sha256[:12]}…"
    )
