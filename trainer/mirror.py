"""Mirror graphs: a single-solver edit and its mirror image in ONE onnxruntime run.

With ``serving.solve_mirror`` each neural pass of an edit answers the mean of its solver's
answer and of the mirror set's solver's answer to the mirrored pose and targets, taken
back (``service.networks.both_views``). Around the fused graphs that is one onnxruntime
run of both views (a set that is its own mirror image) or two (a left and a right solver),
and a dozen small numpy operations, per pass. ``mirror_<key>.onnx`` does all of it in one
run: the mirrored inputs (a column permutation and a sign), the fused graph(s), and the
mean (the same float32 sum and halving), so its answers are bit for bit the numpy way's
(checked here on every graph written, and in ``tests/service/test_engine_mirror.py``).

Composed from the exported fused graphs with ``onnx``, so the service, which does not
install ``onnx``, loads them as files (manifest kind ``mirror``). ``export_all`` writes
them; ``pose-trainer mirror`` adds them to a folder exported before they existed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnx.compose
import onnxruntime as ort
from onnx import TensorProto, helper, numpy_helper

from core.io import sha256_file, write_atomic
from core.manifest import (
    Manifest,
    ModelEntry,
    load_manifest,
    manifest_json,
    stamped,
    write_manifest,
)
from core.skeleton import (
    JOINT_INDEX,
    MIRROR_COLUMNS,
    MIRROR_SIGNS,
    NUM_JOINTS,
    mirror_key,
    mirror_target_columns,
    mirrored_flat,
)


def _names(entry: ModelEntry) -> tuple[str, str, str]:
    pose, targets = (t.name for t in entry.inputs)
    return pose, targets, entry.outputs[0].name


def _columns(
    entry: ModelEntry, back_entry: ModelEntry
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``core.skeleton.mirror_target_columns`` of a fused graph's set and its mirror set's."""
    return mirror_target_columns(
        [JOINT_INDEX[j] for j in entry.joints], [JOINT_INDEX[j] for j in back_entry.joints]
    )


def mirror_graph(own: onnx.ModelProto, back: onnx.ModelProto | None, entry: ModelEntry,
                 back_entry: ModelEntry) -> onnx.ModelProto:  # fmt: skip
    """The mirror graph of fused graph ``own`` (``entry``) and the fused graph of its mirror
    set (``back``, ``back_entry``; None where the set is its own mirror image: both views
    then go through ``own`` as one run of twice the rows)."""
    pose, targets, solved = _names(entry)
    own_cols, other, signs = _columns(entry, back_entry)
    # the mirror set's targets, in its input order, from this set's targets' columns
    pick = [own_cols.tolist().index(c) for c in other.tolist()]
    consts: dict[str, np.ndarray] = {
        "m_cols": np.asarray(MIRROR_COLUMNS, dtype=np.int64),
        "m_signs": MIRROR_SIGNS.astype(np.float32),
        "m_pick": np.asarray(pick, dtype=np.int64),
        "m_tsigns": signs.astype(np.float32),
        "m_half": np.asarray(0.5, dtype=np.float32),
    }
    inits = [numpy_helper.from_array(v, k) for k, v in consts.items()]
    node = helper.make_node
    nodes = [
        node("Gather", [pose, "m_cols"], ["m_xg"], axis=1),
        node("Mul", ["m_xg", "m_signs"], ["m_x"]),
        node("Gather", [targets, "m_pick"], ["m_tg"], axis=1),
        node("Mul", ["m_tg", "m_tsigns"], ["m_t"]),
    ]
    a = onnx.compose.add_prefix(own, "a_")
    if back is None:  # one run of both views: the mirrored rows below the caller's
        opset = max(o.version for o in own.opset_import if o.domain in ("", "ai.onnx"))
        halves: dict[str, Any] = {"num_outputs": 2} if opset >= 18 else {}  # equal halves
        nodes += [
            node("Concat", [pose, "m_x"], [f"a_{pose}"], axis=0),
            node("Concat", [targets, "m_t"], [f"a_{targets}"], axis=0),
            *a.graph.node,
            node("Split", [f"a_{solved}"], ["m_own", "m_other"], axis=0, **halves),
        ]
        inits += a.graph.initializer
    else:  # two graphs in one run: this set's on the pose, the mirror set's on its image
        b = onnx.compose.add_prefix(back, "b_")
        bp, bt, bs = _names(back_entry)
        nodes += [
            node("Identity", [pose], [f"a_{pose}"]),
            node("Identity", [targets], [f"a_{targets}"]),
            node("Identity", ["m_x"], [f"b_{bp}"]),
            node("Identity", ["m_t"], [f"b_{bt}"]),
            *a.graph.node,
            *b.graph.node,
            node("Identity", [f"a_{solved}"], ["m_own"]),
            node("Identity", [f"b_{bs}"], ["m_other"]),
        ]
        inits += [*a.graph.initializer, *b.graph.initializer]
    nodes += [
        node("Gather", ["m_other", "m_cols"], ["m_og"], axis=1),
        node("Mul", ["m_og", "m_signs"], ["m_back"]),
        node("Add", ["m_own", "m_back"], ["m_sum"]),
        node("Mul", ["m_sum", "m_half"], [solved]),
    ]
    spec = helper.make_tensor_value_info
    graph = helper.make_graph(
        nodes, f"mirror_{entry.key}",
        [spec(pose, TensorProto.FLOAT, ["batch", 3 * NUM_JOINTS]),
         spec(targets, TensorProto.FLOAT, ["batch", len(own_cols)])],
        [spec(solved, TensorProto.FLOAT, ["batch", 3 * NUM_JOINTS])],
        inits,
    )  # fmt: skip
    model = helper.make_model(graph, opset_imports=own.opset_import, producer_name="marionette")
    model.ir_version = own.ir_version
    onnx.checker.check_model(model)
    return model


def _check(path: Path, own: Path, back: Path, entry: ModelEntry, back_entry: ModelEntry) -> None:
    """Raise unless the mirror graph at ``path`` answers as the fused graphs and numpy do,
    bit for bit, on 1 and 37 random rows."""
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    run = {
        p: ort.InferenceSession(str(p), opts, providers=["CPUExecutionProvider"])
        for p in {path, own, back}
    }
    pose, targets, _ = _names(entry)
    bp, bt, _ = _names(back_entry)
    own_cols, other, signs64 = _columns(entry, back_entry)
    signs = signs64.astype(np.float32)
    rng = np.random.default_rng(0)
    for n in (1, 37):
        x = (rng.standard_normal((n, 3 * NUM_JOINTS)) * 0.4).astype(np.float32)
        canvas = (rng.standard_normal((n, 3 * NUM_JOINTS)) * 0.4).astype(np.float32)
        mine = run[own].run(None, {pose: x, targets: canvas[:, own_cols]})[0]
        theirs = run[back].run(None, {bp: mirrored_flat(x), bt: canvas[:, other] * signs})[0]
        want = (mine + mirrored_flat(theirs)) * np.float32(0.5)
        got = run[path].run(None, {pose: x, targets: canvas[:, own_cols]})[0]
        if not np.array_equal(got, want):
            raise RuntimeError(f"{path.name}: not the fused graphs' mean, bit for bit")


def mirror_entries(models_dir: Path, fused: dict[str, ModelEntry]) -> list[ModelEntry]:
    """Write ``mirror_<key>.onnx`` for every fused graph whose mirror set has one, each
    checked against the fused graphs; their manifest entries."""
    out = []
    for key, entry in sorted(fused.items()):
        back_entry = fused.get(mirror_key(key))
        if back_entry is None:
            continue
        own_path, back_path = models_dir / entry.file, models_dir / back_entry.file
        back = None if back_entry.key == key else onnx.load(str(back_path))
        model = mirror_graph(onnx.load(str(own_path)), back, entry, back_entry)
        path = models_dir / f"mirror_{key}.onnx"
        write_atomic(path, model.SerializeToString())
        try:
            _check(path, own_path, back_path, entry, back_entry)
        except RuntimeError:
            path.unlink()  # never left beside the models as if it were one of them
            raise
        params = entry.parameters + (0 if back is None else back_entry.parameters)
        out.append(
            entry.model_copy(
                update={
                    "name": f"mirror:{key}",
                    "kind": "mirror",
                    "file": path.name,
                    "sha256": sha256_file(path),
                    "bytes": path.stat().st_size,
                    "parameters": params,
                }
            )
        )
    return out


def add_mirror_graphs(models_dir: Path) -> Manifest:
    """(Re)write ``models_dir``'s mirror graphs from its fused graphs and its manifest with
    their entries: a new version (it hashes every file), networks and serving unchanged."""
    from core.manifest import model_version
    from trainer.model_card import write_model_card

    manifest = load_manifest(models_dir, verify=True)
    kept = [m for m in manifest.models if m.kind != "mirror"]
    entries = [*kept, *mirror_entries(models_dir, manifest.fused())]
    out = manifest.model_copy(
        update={"models": entries, "version": model_version(entries, manifest.serving)}
    )
    out = stamped(Manifest.model_validate(manifest_json(out)))
    write_manifest(models_dir, out)
    write_model_card(models_dir, out)
    return out
