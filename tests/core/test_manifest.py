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
