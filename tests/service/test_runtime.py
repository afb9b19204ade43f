"""onnxruntime wrappers (service.runtime): a big batch runs in blocks of ROW_BLOCK rows,
and every row's answer is the one a single run of the whole batch gives, bit for bit."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service import runtime
from service.engine import Engine
from service.problems import SolveProblem
from tests.conftest import PosePairs


def test_blocked_runs_equal_one_run_bit_for_bit(engine: Engine, real_poses: PosePairs) -> None:
    net = engine.fused["left_wrist+right_wrist"]
    assert isinstance(net, runtime.Net)
    n = 2 * runtime.ROW_BLOCK + 37  # two whole blocks and a part
    rows = np.resize(np.arange(len(real_poses.poses)), n)
    pose = real_poses.poses[rows].reshape(n, -1).astype(np.float32)
    wrists = [JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]]
    targets = real_poses.poses[rows[::-1]][:, wrists].reshape(n, -1).astype(np.float32)
    whole = net.session.run([net.output], dict(zip(net.inputs, (pose, targets), strict=True)))[0]
    got = net(pose, targets)
    assert got.shape == whole.shape == (n, 63)
    assert np.array_equal(got, whole)
    for _ in range(2):  # bound runs of a few rows: each shape's buffers, reused in turn
        for r in range(1, runtime.FEW_ROWS + 1):
            assert np.array_equal(net(pose[r : 2 * r], targets[r : 2 * r]), whole[r : 2 * r])
    assert net(pose[:0], targets[:0]).shape == (0, 63)


def test_bound_runs_in_threads_keep_their_own_buffers(
    engine: Engine, real_poses: PosePairs
) -> None:
    """Two threads running one network at once, each on its own rows (one and two at a
    time): every answer is its rows' own, as one run of the whole batch gives it."""
    net = engine.fused["left_wrist+right_wrist"]
    n = 64
    pose = real_poses.poses[np.resize(real_poses.starts, n)].reshape(n, -1).astype(np.float32)
    targets = pose[::-1, :6].copy()
    whole = net.session.run([net.output], dict(zip(net.inputs, (pose, targets), strict=True)))[0]
    wrong: list[int] = []

    def work(rows: int) -> None:
        for _ in range(20):
            for s in range(0, n, rows):
                if not np.array_equal(
                    net(pose[s : s + rows], targets[s : s + rows]), whole[s : s + rows]
                ):
                    wrong.append(s)

    threads = [threading.Thread(target=work, args=(r,)) for r in (1, 2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert wrong == []


def test_a_big_batch_answers_as_its_items_alone(engine: Engine, real_poses: PosePairs) -> None:
    """Items past the first block of a batch answer as they do alone (rows mirrored too:
    2 views per item, so a 300-item batch runs its networks on 600 rows)."""
    n = 300
    starts = real_poses.poses[np.resize(real_poses.starts, n)]
    goals = real_poses.poses[np.resize(real_poses.goals, n)]
    joints = np.asarray([JOINT_INDEX["left_wrist"], JOINT_INDEX["right_ankle"]])
    idx = np.tile(joints, (n, 1))
    batch = engine.solve_arrays(starts, idx, goals[:, joints])
    for i in (0, 255, 256, 299):
        alone = engine.solve_arrays(starts[i : i + 1], idx[i : i + 1], goals[i : i + 1][:, joints])
        assert np.array_equal(batch.pose[i], alone.pose[0]), i


def test_each_few_rows_shape_runs_on_its_own_session(models_dir: Path) -> None:
    """A few-rows shape's runs go to a session of their own (onnxruntime runs a session's
    first shape fastest), made once and shared by threads: the first shape the network's
    own session while nothing has run on it, the others new ones; after a batch's blocks
    (on the network's session) every shape a new one."""
    engine = Engine(models_dir)
    one, two = ((1, 63), (1, 6)), ((2, 63), (2, 6))
    few = engine.fused["left_wrist+right_wrist"].few
    assert few.session_for(two) is few.session and few.session_for(two) is few.session
    assert few.session_for(one) is few.session_for(one) is not few.session
    net = engine.fused["left_ankle+right_ankle"]
    rows = runtime.FEW_ROWS + 1
    net(np.zeros((rows, 63), np.float32), np.zeros((rows, 6), np.float32))
    assert net.few.session_for(one) is not net.few.session
    # three and four rows run on the shared session: at most two sessions a network
    three = ((3, 63), (3, 6))
    assert few.session_for(three) is few.session
    assert len({id(s) for s in few.sessions.values()} | {id(few.session)}) == 2


def test_sessions_made_after_load_are_the_verified_networks(
    models_dir: Path, real_poses: PosePairs, tmp_path: Path
) -> None:
    """A few-rows shape's own session is made on first use, long after load, from the
    file read again and checked (sha256): the bytes are not kept from load (~27 MiB). A
    models folder changed under a running engine (another network copied over a file, a
    file removed) gave that shape another network's answers, or a 500 while ready said 200
    (a review); now such a shape runs on the network's own session, made at load, and every
    answer is the verified network's. A file changed between the manifest's check and the
    read is refused at load."""
    import shutil

    from core.manifest import ManifestError, load_manifest

    folder = tmp_path / "models"
    shutil.copytree(models_dir, folder)
    engine, ref = Engine(folder), Engine(models_dir)
    idx = np.array([JOINT_INDEX["left_wrist"], JOINT_INDEX["right_wrist"]])
    start, goal = real_poses.poses[real_poses.starts[0]], real_poses.poses[real_poses.goals[0]]

    def lone(e: Engine, mirror: bool) -> np.ndarray:  # a lone edit: its own in-place path
        p = SolveProblem(pose=start, target_idx=idx, target_pos=goal[idx], weights=np.ones(2),
                         n_targets=2, mirror=mirror)  # fmt: skip
        return e.solve([p])[0].pose

    lone(engine, False)  # one row a pass: the network's own session
    by_name = {e.name: e for e in load_manifest(folder).models}
    (folder / by_name["fused:left_wrist+right_wrist"].file).write_bytes(
        (folder / by_name["fused:left_ankle+right_ankle"].file).read_bytes()
    )
    (folder / by_name["mirror:left_wrist+right_wrist"].file).unlink()
    for mirror in (True, False):  # two rows a pass (the edit and its mirror): asked now
        assert np.array_equal(lone(engine, mirror), lone(ref, mirror)), mirror
    few = engine.fused["left_wrist+right_wrist"].few
    assert [s is few.session for s in few.sessions.values()] == [True, True]  # no file's
    other = engine.fused["left_ankle+right_ankle"].few  # its file as it was: a session made
    lone_pair = ((1, 63), (1, 6)), ((2, 63), (2, 6))
    assert [other.session_for(s) is other.session for s in lone_pair] == [True, False]
    entry = by_name["autoencoder"]  # a file whose bytes are not the manifest's
    path = folder / entry.file
    path.write_bytes(path.read_bytes() + b"\0")
    with pytest.raises(ManifestError, match="changed since read"):
        runtime.Net(path, entry, runtime.session_options())


def test_a_network_keeps_no_copy_of_its_file(models_dir: Path) -> None:
    """A network's sessions keep none of the bytes they are made from: onnxruntime's Python
    session held them for life, as did the network for its few-rows sessions, ~27 MiB of
    every worker's RSS for the served networks (2026-12-06: 331 -> 304 MiB once ready). Its
    own few-rows sessions, made later from the file read again, keep none either."""
    import gc
    import tracemalloc

    from core.manifest import ModelEntry, load_manifest

    def size_of(e: ModelEntry) -> int:
        return (models_dir / e.file).stat().st_size

    entry = max(load_manifest(models_dir).models, key=size_of)  # a completion network's
    size = size_of(entry)
    options = runtime.session_options()
    tracemalloc.start()
    try:
        net = runtime.Net(models_dir / entry.file, entry, options)
        for rows in (1, 2):  # the first shape on the network's session, the second its own
            net(*(np.zeros((rows, int(i.shape[-1])), np.float32) for i in entry.inputs))
        gc.collect()
        kept, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len({id(s) for s in net.few.sessions.values()}) == 2
    assert kept < size / 4, (kept, size)
