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
- ``real_poses``: real canonical poses and (start, goal) pairs from ``small_dataset``.
- ``bvh_files``: the character files of :data:`tests.character_files.FILES` (five studios'
  BVH), extracted once; read them, never write them.

Every test that uses one of these (directly or through another fixture) is marked
``mocap`` by :func:`pytest_collection_modifyitems`: ``pytest -m "not mocap"`` runs the
archive-free part; CI runs everything.

A session of a folder of tests (``make test``) starts two things as it starts, while the
tests are collected: the kernels' compile when numba's cache holds none for these sources
(two processes; waited for before the first test) and the ``mocap_clips`` extraction
(:func:`pytest_sessionstart`). Under pytest-xdist (``make test``: two workers, whole files
each) the controller compiles, before it hands out the first test, and each worker extracts
its own clips (session fixtures are set up once per worker). A test marked ``alone`` (it
bounds wall time) runs while the other worker runs nothing (``tests/alone.py``).

Synthetic (no mocap): ``synthetic_poses`` has the same shape as ``real_poses``, built from
the rest pose with random bone rotations; use it wherever any valid pose will do, and keep
``real_poses`` for assertions about real motion (accuracy on real edits).
"""

from __future__ import annotations

import functools
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from tests.alone import _alone_or_shared  # noqa: F401  (autouse: tests marked ``alone``)

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


@functools.cache
def _gnu_tar(tar: str) -> bool:
    out = subprocess.run([tar, "--version"], capture_output=True, text=True, check=False)
    return "GNU tar" in out.stdout


def untar(tar: str, archive: Path, out: Path, members: Sequence[str]) -> list[str]:
    """The command that extracts ``members`` of the .tar.xz ``archive`` into ``out``. GNU
    tar is told to stop once it has them all (``--occurrence``: the archives hold each
    member once), instead of decompressing the rest of the archive for nothing (the Bandai
    one: ~6 s of CPU, most of it past the members the tests take)."""
    first = ["--occurrence=1"] if _gnu_tar(tar) else []
    return [tar, "-xJf", str(archive), "-C", str(out), *first, *members]


# --------------------------------------------------------------------------------------
# Work started when the session starts, while the tests are collected (one core does that:
# the other was idle), and waited for where it is needed
# --------------------------------------------------------------------------------------
#: Each fills part of numba's cache (``core.jit``) with the kernels the engine compiles at
#: its first load, in a process of its own: two halves of about the same CPU time (each
#: ~27 s alone on this 2-core host, the whole ~60 s in one process). ``compiled.warm`` warms
#: the reach kernels first: here the other process compiles them (no kernel twice at once).
_KERNEL_WARMS = (
    "from core import compiled_fabrik, compiled_reach\n"
    "compiled_fabrik.warm()\n"
    "compiled_reach.warm()\n",
    "from core import compiled, compiled_characters, compiled_reach\n"
    "compiled_characters.warm()\n"
    "compiled_reach.warm = lambda: None  # (the other process's)\n"
    "compiled.warm()\n",
)


@dataclass
class _Prefetch:
    """What :func:`pytest_sessionstart` started: the ``mocap_clips`` extraction (into
    ``clips_root``, from the archives in ``clips_from``; taken over by the fixture) and the
    kernels' compile (waited for once the tests are collected, before the first runs)."""

    clips: list[subprocess.Popen[bytes]] = field(default_factory=list)
    clips_root: Path = Path()
    clips_from: Path | None = None
    kernels: list[subprocess.Popen[bytes]] = field(default_factory=list)


_PREFETCH = _Prefetch()


def _kernels_cached() -> bool:
    """Whether numba's cache folder for this tree's ``core/`` holds compiled kernels (the
    folder ``core.jit`` chose, as ``bench.ab`` finds it). True when ``core.jit`` cannot be
    imported: the tests that import it say why."""
    try:
        import core.jit
    except Exception:
        return True
    here = os.path.dirname(os.path.abspath(core.jit.__file__))
    folder = Path(os.environ["NUMBA_CACHE_DIR"]) / core.jit.numba_subfolder(here)
    return any(folder.glob("*.nbi"))


def pytest_sessionstart(session: pytest.Session) -> None:
    """Start what most sessions wait for first, so that it runs while the tests are
    collected (~7 s of one core): the kernels' compile, when numba's cache holds none for
    these sources (a fresh checkout, as CI's, or ``core/`` edited: the suite's first engine
    compiled them all in one process, ~45-60 s), in two processes; and the ``mocap_clips``
    extraction (~6 s of xz). Neither changes what a test sees: the kernels are numba's own,
    compiled as an engine compiles them; the clips are extracted by the same command. Only
    for a folder of tests (``make test``'s ``tests``): a file or a test given alone may need
    neither (``docker/smoke.sh``'s container check)."""
    config = session.config
    folders = [Path(str(arg).split("::")[0]).is_dir() for arg in config.args]
    if config.option.collectonly or not any(folders):
        return
    # Under pytest-xdist (``make test``: ``-n 2``) the controller compiles the kernels (its
    # workers would each compile them, at once) and runs no test: the workers extract clips.
    worker = hasattr(config, "workerinput")
    if not worker and not _kernels_cached():
        _PREFETCH.kernels = [
            subprocess.Popen(
                [sys.executable, "-c", code],
                cwd=REPO_ROOT,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
            )
            for code in _KERNEL_WARMS
        ]
    if config.pluginmanager.has_plugin("dsession"):  # the xdist controller
        return
    mocap, tar = _mocap_path(), shutil.which("tar")
    if tar and all((mocap / a).is_file() for a in (BANDAI_ARCHIVE, CMU_ARCHIVE)):
        factory: pytest.TempPathFactory = config._tmp_path_factory  # type: ignore[attr-defined]
        _PREFETCH.clips_root = factory.mktemp("mocap")
        _PREFETCH.clips_from = mocap
        _PREFETCH.clips = _untar_clips(tar, mocap, _PREFETCH.clips_root)


def pytest_collection_finish(session: pytest.Session) -> None:
    """The kernels compiled, before the first test (a test that compiled one meanwhile would
    compile it a second time). A compile that failed is only reported: the tests that use
    the kernel compile it again and fail with the error."""
    _wait_for_kernels(session.config)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_node_collection_finished(node: Any, ids: list[str]) -> None:
    """Under xdist: the controller's compile waited for before it hands out the first tests
    (as each worker reports its collection; only the first call waits)."""
    _wait_for_kernels(node.config)


def _wait_for_kernels(config: pytest.Config) -> None:
    procs, _PREFETCH.kernels = _PREFETCH.kernels, []
    for proc in procs:
        _, err = proc.communicate()
        if proc.returncode:
            reporter = config.pluginmanager.get_plugin("terminalreporter")
            if reporter is not None:
                reporter.write_line(f"kernel warm-up failed: {err.decode(errors='replace')}")


def pytest_sessionfinish(session: pytest.Session) -> None:
    """Stop what was started and never waited for (an interrupted collection, a session
    that used no clips)."""
    for proc in (*_PREFETCH.kernels, *_PREFETCH.clips):
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


#: The container check's figures (tests/deploy/conftest.py), as its tests' reports bring them.
_SMOKE_FIGURES: dict[str, str] = {}


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    for name, value in report.user_properties:
        if name == "smoke_figures":
            _SMOKE_FIGURES.update(value)


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if _SMOKE_FIGURES:
        terminalreporter.section("container figures")
        for name, value in _SMOKE_FIGURES.items():
            terminalreporter.write_line(f"SMOKE {name}={value}")


def _mocap_path() -> Path:
    env = os.environ.get("MARIONETTE_MOCAP")
    return Path(env) if env else REPO_ROOT.parent / "shared" / "mocap"


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """The mocap archive folder; skips the test when it is absent."""
    path = _mocap_path()
    missing = [a for a in (BANDAI_ARCHIVE, CMU_ARCHIVE) if not (path / a).is_file()]
    if missing:
        pytest.skip(
            f"mocap archives {missing} not found in {path} "
            "(set MARIONETTE_MOCAP to the folder holding them)"
        )
    return path


def _untar_clips(tar: str, mocap: Path, root: Path) -> list[subprocess.Popen[bytes]]:
    """Both archives' clips extracted into ``root``, in parallel (the processes, running)."""
    return [
        subprocess.Popen(untar(tar, mocap / archive, root, members), stderr=subprocess.PIPE)
        for archive, members in ((BANDAI_ARCHIVE, BANDAI_MEMBERS), (CMU_ARCHIVE, CMU_MEMBERS))
    ]


@pytest.fixture(scope="session")
def mocap_clips(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> MocapClips:
    """Extract a few real clips from both archives (once per session, both in parallel;
    started when the session starts, :func:`pytest_sessionstart`, when it could be)."""
    tar = shutil.which("tar")
    if tar is None:
        pytest.skip("the 'tar' command is needed to extract test clips")
    if _PREFETCH.clips and _PREFETCH.clips_from == mocap_dir:
        root, procs = _PREFETCH.clips_root, _PREFETCH.clips
        _PREFETCH.clips = []  # (waited for here, from now on)
    else:
        root = tmp_path_factory.mktemp("mocap")
        procs = _untar_clips(tar, mocap_dir, root)
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
        subprocess.Popen(untar(tar, mocap_dir / archive, root, members), stderr=subprocess.PIPE)
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


#: Fixtures that need the mocap archives; a test using any of them is marked ``mocap``.
MOCAP_FIXTURES = frozenset(
    {"mocap_dir", "mocap_clips", "more_mocap", "small_dataset", "real_poses"}
)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test that (transitively) uses a mocap fixture with ``mocap``; give each
    schemathesis case its own id (:func:`_own_id`)."""
    for item in items:
        if MOCAP_FIXTURES.intersection(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.mocap)
        _own_id(item)


def _own_id(item: pytest.Item) -> None:
    """pytest 9.2 builds a test's id from its function's name and its parametrize ids, so
    schemathesis 4.32's cases (one per API operation, ``test_schemathesis[POST /v1/solve]``
    by name) all had the one id ``test_contract.py::test_schemathesis``. One process ran
    them all; pytest-xdist, which hands tests out by id, ran the first alone (10 requests,
    test_contract's volume check failed). The name's bracket becomes the id's."""
    node_id, original = getattr(item, "_id", None), getattr(item, "originalname", None)
    if node_id is None or original is None or getattr(node_id, "params", "") is not None:
        return
    if item.name.startswith(f"{original}[") and item.name.endswith("]"):
        item._id = node_id.with_params(item.name[len(original) + 1 : -1])  # type: ignore[attr-defined]


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
def real_poses(small_dataset: Path) -> PosePairs:
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
    return PosePairs(
        poses=data.positions.astype(np.float64),
        starts=anchors[keep],
        goals=partners[keep],
    )


@dataclass(frozen=True)
class PosePairs:
    """Poses and (start, goal) pairs of indices into them: ``real_poses`` (canonical frames
    of real clips) or ``synthetic_poses`` (the rest pose plus random rotations)."""

    poses: Any  # (N, 21, 3) float64 metres
    starts: Any  # indices of start poses
    goals: Any  # indices of target poses: a moderate change of the start

    def pose_dict(self, i: int, transform: Any = None) -> dict[str, list[float]]:
        from core.skeleton import JOINT_NAMES

        p = self.poses[i] if transform is None else transform(self.poses[i])
        return {n: [float(v) for v in p[j]] for j, n in enumerate(JOINT_NAMES)}


#: The older name (the real set came first).
RealPoses = PosePairs


def on_random_bodies(pairs: PosePairs, seed: int) -> tuple[Any, Any]:
    """The (start, goal) poses of ``pairs`` rebuilt on random asymmetric bodies (``core.bodies``,
    ±25 % per bone), one body per pair, the same for its start and goal."""
    import numpy as np

    from core.bodies import body_lengths, random_bodies, rebuild

    start, goal = pairs.poses[pairs.starts], pairs.poses[pairs.goals]
    bodies = random_bodies(np.random.default_rng(seed), len(start), scale=0.25, symmetric=False)
    lengths = body_lengths(goal, bodies)
    return rebuild(start, bodies, lengths), rebuild(goal, bodies, lengths)


def edit_problems(starts: Any, goals: Any, names: tuple[str, ...]) -> list[Any]:
    """One soft neural ``SolveProblem`` per (start, goal) pair: the joints ``names``
    dragged to where the goal has them, weight 1, no pins."""
    import numpy as np

    from core.skeleton import JOINT_INDEX
    from service.problems import SolveProblem

    idx = np.asarray([JOINT_INDEX[n] for n in names], dtype=np.intp)
    return [
        SolveProblem(
            pose=s, target_idx=idx, target_pos=g[idx], weights=np.ones(len(idx)), n_targets=len(idx)
        )
        for s, g in zip(starts, goals, strict=True)
    ]


#: Largest random turn (degrees) of a bone about its parent joint, by the child joint's
#: name without its side: the spine and head bend a little, the limbs more, so every pose
#: stays upright.
SYNTH_MAX_DEG: dict[str, float] = {
    "spine1": 10.0,
    "spine2": 10.0,
    "neck": 15.0,
    "head": 20.0,
    "collar": 10.0,
    "shoulder": 45.0,
    "elbow": 50.0,
    "wrist": 30.0,
    "hip": 30.0,
    "knee": 35.0,
    "ankle": 30.0,
    "foot": 20.0,
}
SYNTH_PAIRS = 64
SYNTH_SEED = 20240610


def axis_angle(axis: Any, angle: Any) -> Any:
    """Rotation matrices ``[..., 3, 3]`` from unit axes ``[..., 3]`` and angles ``[...]``
    in radians (Rodrigues)."""
    import numpy as np

    x, y, z = axis[..., 0], axis[..., 1], axis[..., 2]
    c, s = np.cos(angle), np.sin(angle)
    t = 1.0 - c
    return np.stack(
        [
            np.stack([c + x * x * t, x * y * t - z * s, x * z * t + y * s], axis=-1),
            np.stack([y * x * t + z * s, c + y * y * t, y * z * t - x * s], axis=-1),
            np.stack([z * x * t - y * s, z * y * t + x * s, c + z * z * t], axis=-1),
        ],
        axis=-2,
    )


def pose_from_rotations(local: Any, yaw: Any, root: Any) -> Any:
    """Forward kinematics of the rest pose: ``local[..., j, :, :]`` turns joint ``j``'s bone
    (and everything below it) about its parent joint, root outwards; then the whole body
    turns by ``yaw`` about +Y and moves by ``root``. Bone lengths stay the rest lengths."""
    import numpy as np

    from core.rest import rest_pose
    from core.skeleton import NUM_JOINTS, PARENTS

    rest = rest_pose()
    c, s = np.cos(yaw), np.sin(yaw)
    zero, one = np.zeros_like(yaw), np.ones_like(yaw)
    heading = np.stack(
        [np.stack([c, zero, s], -1), np.stack([zero, one, zero], -1), np.stack([-s, zero, c], -1)],
        axis=-2,
    )
    turn = [heading] * NUM_JOINTS  # accumulated rotation of each joint's bone
    pos = np.zeros((*np.shape(yaw), NUM_JOINTS, 3))
    pos[..., 0, :] = rest[0] + root
    for j, parent in enumerate(PARENTS):
        if parent >= 0:
            turn[j] = turn[parent] @ local[..., j, :, :]
            pos[..., j, :] = pos[..., parent, :] + turn[j] @ (rest[j] - rest[parent])
    return pos


def make_synthetic_poses(seed: int = SYNTH_SEED, n: int = SYNTH_PAIRS) -> PosePairs:
    """``n`` synthetic start poses, then ``n`` goals (see :func:`synthetic_poses`)."""
    import numpy as np

    from core.skeleton import JOINT_NAMES, NUM_JOINTS

    rng = np.random.default_rng(seed)
    max_deg = np.array([0.0] + [SYNTH_MAX_DEG[j.split("_")[-1]] for j in JOINT_NAMES[1:]])
    axis = rng.normal(size=(n, NUM_JOINTS, 3))
    axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
    local = axis_angle(axis, np.radians(rng.uniform(0.0, 1.0, (n, NUM_JOINTS)) * max_deg))
    yaw = rng.uniform(-np.pi, np.pi, size=n)
    root = rng.uniform(-0.5, 0.5, size=(n, 3)) * np.array([1.0, 0.05, 1.0])
    edit = np.broadcast_to(np.eye(3), (n, NUM_JOINTS, 3, 3)).copy()
    for i in range(n):
        joints = rng.choice(np.arange(1, NUM_JOINTS), size=int(rng.integers(2, 5)), replace=False)
        turn_axis = rng.normal(size=(len(joints), 3))
        turn_axis /= np.linalg.norm(turn_axis, axis=-1, keepdims=True)
        angle = np.radians(rng.uniform(10.0, 40.0, len(joints)))
        edit[i, joints] = axis_angle(turn_axis, angle)
    starts = pose_from_rotations(local, yaw, root)
    goals = pose_from_rotations(local @ edit, yaw, root)
    return PosePairs(
        poses=np.concatenate([starts, goals]), starts=np.arange(n), goals=np.arange(n, 2 * n)
    )


@pytest.fixture(scope="session")
def synthetic_poses() -> PosePairs:
    """Synthetic poses (numpy only, seeded; no mocap needed), shaped like ``real_poses``:
    the rest pose with each bone turned at random about its parent joint, root outwards
    (bone lengths exact, upright), under a random yaw and root offset; each goal turns 2-4
    bones of its start by a further 10-40 degrees."""
    return make_synthetic_poses()


def traced(work: Any, settle: float = 0.0, below: int = 0) -> tuple[Any, float, int, int]:
    """``work()`` with the cyclic collector off and tracemalloc on: its result, seconds,
    and the bytes it left held and at its peak (``settle`` s at most for what it held to
    fall below ``below`` bytes: a thread of the app may still let go). Memory held without
    the cyclic collector is what a reference cycle would keep."""
    import gc
    import time
    import tracemalloc

    gc.collect()
    gc.disable()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        start = time.perf_counter()
        got = work()
        took = time.perf_counter() - start
        until = time.monotonic() + settle
        while tracemalloc.get_traced_memory()[0] - base >= below and time.monotonic() < until:
            time.sleep(0.05)
        held, peak = (m - base for m in tracemalloc.get_traced_memory())
    finally:
        tracemalloc.stop()
        gc.enable()
    return got, took, held, peak


def make_client(models_dir: Path, unchecked: dict[str, Any] | None = None, **settings: Any) -> Any:
    """A test client of an app with ``settings``, and ``unchecked`` set past their bounds
    (a deadline of 1e-6 s, to see a 504 before any work: no deployment may set it)."""
    from fastapi.testclient import TestClient

    from service.app import create_app
    from service.settings import Settings

    chosen = Settings(models_dir=models_dir, **settings).model_copy(update=unchecked or {})
    app = create_app(chosen, load_in_background=False)
    return TestClient(app, raise_server_exceptions=False)


@pytest.fixture(scope="session")
def client(models_dir: Path) -> Iterator[Any]:
    with make_client(models_dir) as c:
        yield c


@pytest.fixture(scope="session")
def bvh_files(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """:func:`tests.character_files.extract_bvh` once per session (each module extracting
    its own copy cost ~10 s of xz a module)."""
    from tests.character_files import extract_bvh

    return extract_bvh(mocap_dir, tmp_path_factory.mktemp("bvh_files"))
