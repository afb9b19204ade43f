"""Shared pytest fixtures.

Mocap (real data, session-scoped):

- ``mocap_dir``: the folder with the mocap archives (``../shared/mocap`` next to the repo,
  or ``$MARIONETTE_MOCAP``); tests that need it are skipped when it is absent.
- ``mocap_clips``: a few real clips extracted from both archives into a temp folder laid out
  like the archives (so the dataset builder reads it as extracted folders).
- ``small_dataset``: a real ``poses.npz`` built from ``mocap_clips`` by the same code path as
  ``pose-trainer dataset`` (train/val/test all non-empty).
- ``more_mocap``: a few real files of the three multi-body archives (CMU ASF/AMC, ReActIdle,
  AnimatedDrawings), laid out like the archives; skipped when those archives are absent.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from service.engine import Engine

REPO_ROOT = Path(__file__).resolve().parents[1]
BANDAI_ARCHIVE = "bandai-namco-research-motiondataset.tar.xz"
CMU_ARCHIVE = "cmu-dance.tar.xz"
_B1 = "dataset/Bandai-Namco-Research-Motiondataset-1/data"
_B2 = "dataset/Bandai-Namco-Research-Motiondataset-2/data"
#: Bandai clips: 4 walks (2 per dataset) and 3 raise-up-left-hand, so both contents reach
#: every split.
BANDAI_MEMBERS: tuple[str, ...] = (
    f"{_B1}/dataset-1_walk_normal_001.bvh",
    f"{_B1}/dataset-1_walk_normal_002.bvh",
    f"{_B2}/dataset-2_walk_normal_001.bvh",
    f"{_B2}/dataset-2_walk_active_001.bvh",
    f"{_B2}/dataset-2_raise-up-left-hand_normal_001.bvh",
    f"{_B2}/dataset-2_raise-up-left-hand_normal_002.bvh",
    f"{_B2}/dataset-2_raise-up-left-hand_active_001.bvh",
)
#: CMU clips: 3 salsa (60 fps), 1 martial (120 fps), and the rest skeleton (must be skipped).
CMU_MEMBERS: tuple[str, ...] = (
    "train_data_bvh/salsa/01.bvh",
    "train_data_bvh/salsa/10.bvh",
    "train_data_bvh/salsa/25.bvh",
    "train_data_bvh/martial/04.bvh",
    "train_data_bvh/standard.bvh",
)


@dataclass(frozen=True)
class MocapClips:
    """Real clips extracted into ``root`` (paths as in the archives)."""

    root: Path
    bandai: tuple[Path, ...]
    cmu: tuple[Path, ...]

    def path(self, member: str) -> Path:
        return self.root / member


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The mocap archive folder; skips the test when it is absent."""
    env = os.environ.get("MARIONETTE_MOCAP")
    path = Path(env) if env else REPO_ROOT.parent / "shared" / "mocap"
    missing = [a for a in (BANDAI_ARCHIVE, CMU_ARCHIVE) if not (path / a).is_file()]
    if missing:
        pytest.skip(
            f"mocap archives {missing} not found in {path} "
            "(set MARIONETTE_MOCAP to the folder holding them)"
        )
    return path


@pytest.fixture(scope="session")
def mocap_clips(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> MocapClips:
    """Extract a few real clips from both archives (once per session, both in parallel)."""
    tar = shutil.which("tar")
    if tar is None:
        pytest.skip("the 'tar' command is needed to extract test clips")
    root = tmp_path_factory.mktemp("mocap")
    procs = [
        subprocess.Popen(
            [tar, "-xJf", str(mocap_dir / archive), "-C", str(root), *members],
            stderr=subprocess.PIPE,
        )
        for archive, members in ((BANDAI_ARCHIVE, BANDAI_MEMBERS), (CMU_ARCHIVE, CMU_MEMBERS))
    ]
    for proc in procs:
        _, err = proc.communicate()
        assert proc.returncode == 0, f"tar failed: {err.decode(errors='replace')}"
    return MocapClips(
        root=root,
        bandai=tuple(root / m for m in BANDAI_MEMBERS),
        cmu=tuple(root / m for m in CMU_MEMBERS if not m.endswith("standard.bvh")),
    )


#: Files of the three multi-body archives (archive -> members), for readers, maps and the
#: holdout split: CMU subjects 07 and 124 (held out) and 10, 16 and 135 (not; 135_06 is also
#: in cmu-dance as martial/06), the 124_02 copy (excluded by the map), two ReActIdle clips,
#: both fair1 skeletons and cmu1.
_ASF = "cmu_asfamc_subset/terryum+Athletic_Movement_Detection@06b5ebe/MocapData"
_KAY = "cmu_asfamc_subset/Kay1794+Mocap-Keyframe-Interpolation@f19d313/mocapPlayer-starter"
_RI = "reactidle_bvh/Enekoassets+ReActIdle@90b0ac7"
_FAIR = "animateddrawings_fair_bvh/facebookresearch+AnimatedDrawings@74ee7f0/examples/bvh"
MORE_MOCAP: dict[str, tuple[str, ...]] = {
    "cmu_asfamc_subset.tar.xz": (
        f"{_KAY}/07-walk.asf",
        f"{_KAY}/07_05-walk.amc",
        f"{_ASF}/10.asf",
        f"{_ASF}/10_01.amc",
        f"{_ASF}/16.asf",
        f"{_ASF}/16_01.amc",
        f"{_ASF}/16_05.amc",
        f"{_ASF}/124.asf",
        f"{_ASF}/124_02.amc",
        f"{_ASF}/124_02 - Copy.amc",
        f"{_KAY}/135-martialArts.asf",
        f"{_KAY}/135_06-martialArts.amc",
    ),
    "reactidle_bvh.tar.xz": (f"{_RI}/genuine/003_genuine.bvh", f"{_RI}/genuine/002_genuine.bvh"),
    "animateddrawings_fair_bvh.tar.xz": (
        f"{_FAIR}/fair1/dab.bvh",
        f"{_FAIR}/fair1/wave_hello.bvh",
        f"{_FAIR}/cmu1/jumping_jacks.bvh",
    ),
}


@pytest.fixture(scope="session")
def more_mocap(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Extract :data:`MORE_MOCAP` (once per session, the archives in parallel); the root of
    the archive layout. Skips when the archives or ``tar`` are absent."""
    missing = [a for a in MORE_MOCAP if not (mocap_dir / a).is_file()]
    if missing:
        pytest.skip(f"mocap archives {missing} not found in {mocap_dir}")
    tar = shutil.which("tar")
    if tar is None:
        pytest.skip("the 'tar' command is needed to extract test clips")
    root = tmp_path_factory.mktemp("more_mocap")
    procs = [
        subprocess.Popen(
            [tar, "-xJf", str(mocap_dir / archive), "-C", str(root), *members],
            stderr=subprocess.PIPE,
        )
        for archive, members in MORE_MOCAP.items()
    ]
    for proc in procs:
        _, err = proc.communicate()
        assert proc.returncode == 0, f"tar failed: {err.decode(errors='replace')}"
    return root


@pytest.fixture(scope="session")
def small_dataset(mocap_clips: MocapClips, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real dataset (.npz) of the few extracted clips, built like the CLI does (seed 0)."""
    from trainer.data.build import build_dataset

    out = tmp_path_factory.mktemp("dataset") / "poses.npz"
    build_dataset(mocap_clips.root, out, seed=0, workers=2, progress=False)
    return out


# --------------------------------------------------------------------------------------
# Models and the service (the shipped models by default; $MARIONETTE_MODELS overrides)
# --------------------------------------------------------------------------------------
@pytest.fixture(scope="session")
def models_dir() -> Path:
    env = os.environ.get("MARIONETTE_MODELS")
    path = Path(env) if env else REPO_ROOT / "models"
    assert (path / "manifest.json").is_file(), f"no trained models at {path}"
    return path


@pytest.fixture(scope="session")
def engine(models_dir: Path) -> Engine:
    from service.engine import Engine

    return Engine(models_dir)


@pytest.fixture(scope="session")
def real_poses(small_dataset: Path) -> RealPoses:
    """Real canonical poses (metres) and pairs 0.2-1 s apart from the same clip."""
    import numpy as np

    from trainer.data.dataset import load_dataset
    from trainer.pairs import partner_ranges, sample_partners

    data = load_dataset(small_dataset)
    lo, hi = partner_ranges(data.clip, data.frame, 30)
    rng = np.random.default_rng(0)
    anchors = np.sort(rng.choice(len(data), size=200, replace=False))
    partners = sample_partners(lo, hi, anchors, rng, frame=data.frame, min_gap=6)
    keep = partners != anchors
    return RealPoses(
        poses=data.positions.astype(np.float64),
        starts=anchors[keep],
        goals=partners[keep],
    )


@dataclass(frozen=True)
class RealPoses:
    poses: Any  # (N, 21, 3) float64 canonical metres
    starts: Any  # indices of start poses
    goals: Any  # indices of target poses, same clip, 0.2-1 s from the start

    def pose_dict(self, i: int, transform: Any = None) -> dict[str, list[float]]:
        from core.skeleton import JOINT_NAMES

        p = self.poses[i] if transform is None else transform(self.poses[i])
        return {n: [float(v) for v in p[j]] for j, n in enumerate(JOINT_NAMES)}


def make_client(models_dir: Path, **settings: Any) -> Any:
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import Settings

    app = create_app(Settings(models_dir=models_dir, **settings), load_in_background=False)
    return TestClient(app, raise_server_exceptions=False)


@pytest.fixture(scope="session")
def client(models_dir: Path) -> Iterator[Any]:
    with make_client(models_dir) as c:
        yield c
