"""Trainer: a tiny end-to-end training on real clips, export, manifest, parity, resume,
determinism and DDP."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnxruntime as ort
import pytest
import torch

from core.io import sha256_file
from core.manifest import ManifestError, load_manifest, model_version
from core.skeleton import JOINT_INDEX
from trainer import stages
from trainer.config import QUICK, TrainConfig, load_config
from trainer.data.dataset import load_dataset
from trainer.export import evaluate, export_all
from trainer.fused import FusedGraph, LeanFusedGraph
from trainer.models import (
    Normaliser,
    SingleSolver,
    SolverBank,
    TiedAutoencoder,
    feature_stats,
    merge_banks,
    target_columns,
)
from trainer.rigid import across_pelvis_t, parent_offsets_t
from trainer.stages import (
    _section,
    config_tag,
    host,
    init_distributed,
)
from trainer.train import (
    Trained,
    completion_loss,
    flat,
    mpjpe_cm,
    reference_lengths,
    solver_losses,
    train_all,
    train_solvers,
)

REPO = Path(__file__).resolve().parents[2]

#: A small but complete configuration: every kind of network, a pair solver included.
TINY: dict[str, Any] = {
    **QUICK,
    "threads": 1,
    "max_train_frames": 3000,
    "max_eval_frames": 500,
    "solver": {
        "epochs": 1,
        "sets": [["left_wrist"], ["left_ankle", "right_ankle"]],
        "long_sets": [["head", "left_wrist", "right_wrist"]],  # a bank of its own
        "long_epochs": 2,
    },
    "completion": {
        "epochs": 1,
        "schemes": [
            ["pelvis", "neck", "left_wrist", "right_wrist", "left_ankle", "right_ankle"],
            ["head", "left_elbow", "right_elbow"],
        ],
        "hidden": [64, 64],
    },
}


def tiny_config(dataset: Path, run_dir: Path, out_dir: Path, **extra: Any) -> TrainConfig:
    overrides = {**TINY, "dataset": str(dataset), "run_dir": str(run_dir), "out_dir": str(out_dir)}
    for key, value in extra.items():
        if isinstance(value, dict):
            overrides[key] = {**overrides.get(key, {}), **value}
        else:
            overrides[key] = value
    return load_config(None, overrides)


@pytest.fixture(scope="module")
def trained(small_dataset: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Trained, Path]:
    root = tmp_path_factory.mktemp("tiny")
    cfg = tiny_config(small_dataset, root / "run", root / "models")
    result = train_all(cfg, fresh=True)
    export_all(cfg, result, evaluate(cfg, result))
    return result, root / "models"


def test_an_export_replaces_a_models_folder_whole_or_not_at_all(
    trained: tuple[Trained, Path], small_dataset: Path, tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:  # fmt: skip
    """An export went file by file into the folder: interrupted, it left new networks
    beside the old manifest (models the service refused, the old ones gone); it also
    overwrote a folder of other files, and left an older export's extra files. Now it is
    written beside the folder and swapped in whole; a folder that is not a models folder
    is refused; what killed exports left beside it is cleared.

    The networks are the fixture's, so each ONNX file is the one the fixture's export
    wrote for the same network: it is copied, not converted again (two more exports of
    ten networks, ~30 s, with nothing to do with the folder); every other step of the
    export runs, the parity of each file with its network included."""
    import trainer.export as export

    result, models = trained

    def exported(module: Any, args: Any, names: Any, output: Any, path: Path, opset: int) -> None:
        shutil.copyfile(models / path.name, path)

    monkeypatch.setattr(export, "_export", exported)
    target = tmp_path / "models"
    shutil.copytree(models, target)
    (target / "stale_solver.onnx").write_bytes(b"an older export's file")
    manifest = (target / "manifest.json").read_bytes()
    cfg = tiny_config(small_dataset, tmp_path / "run", target)
    metrics = evaluate(cfg, result)

    def interrupted(*_: Any) -> None:
        raise KeyboardInterrupt

    with monkeypatch.context() as m:  # interrupted at its last step: nothing replaced
        m.setattr(export, "write_model_card", interrupted)
        with pytest.raises(KeyboardInterrupt):
            export_all(cfg, result, metrics)
    assert (target / "manifest.json").read_bytes() == manifest
    assert (target / "stale_solver.onnx").exists()
    load_manifest(target, verify=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models"]  # no partial folder
    # what exports killed part-way left, hidden, for good (a studio audit, D7: 28 MB for
    # full models): the next export removes those of processes gone (their .old-<pid>
    # folders once the new models are in place), not a running one's, not another folder's
    gone = subprocess.Popen(["true"])
    gone.wait()
    stale = [tmp_path / f".models.partial-{gone.pid}", tmp_path / f".models.old-{gone.pid}"]
    running, other = f".models.partial-{os.getppid()}", f".models-v2.partial-{gone.pid}"
    kept = [tmp_path / running, tmp_path / other]
    for folder in (*stale, *kept):
        folder.mkdir()
        (folder / "encoder.onnx").write_bytes(b"half an export")
    export_all(cfg, result, metrics)  # whole: the older export's file gone
    assert not (target / "stale_solver.onnx").exists()
    load_manifest(target, verify=True)
    assert not any(p.exists() for p in stale)
    assert all((p / "encoder.onnx").is_file() for p in kept)
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "README.md").write_text("a studio's notes")
    with pytest.raises(FileExistsError, match="not a models folder"):
        export_all(tiny_config(small_dataset, tmp_path / "run", notes), result, metrics)
    assert (notes / "README.md").read_text() == "a studio's notes"


def test_manifest_is_valid_and_hashes_verify(trained: tuple[Trained, Path]) -> None:
    _, models = trained
    manifest = load_manifest(models, verify=True)
    kinds = sorted(m.kind for m in manifest.models)
    assert kinds.count("solver") == 3
    assert kinds.count("completion") == 2
    assert manifest.autoencoder("encoder").file == "encoder.onnx"
    assert set(manifest.solvers()) == {
        "left_wrist", "left_ankle+right_ankle", "head+left_wrist+right_wrist"
    }  # fmt: skip
    # a mirror graph where the set's mirror image has a fused graph too (not left_wrist)
    assert set(manifest.mirrors()) == {"left_ankle+right_ankle", "head+left_wrist+right_wrist"}
    assert manifest.provenance.split_seed == 0
    assert manifest.provenance.config["solver"]["other_weight"] == 0.01
    for entry in manifest.models:
        assert entry.metrics, f"{entry.name} has no val/test metrics"
        assert all(np.isfinite(v) for v in entry.metrics.values())
        model = onnx.load(str(models / entry.file))
        onnx.checker.check_model(model, full_check=True)
        batch_dims = [i.type.tensor_type.shape.dim[0].dim_param for i in model.graph.input]
        assert all(batch_dims), f"{entry.file}: batch axis is not dynamic"


def test_a_folder_source_is_recorded_as_the_folder_read(
    trained: tuple[Trained, Path], mocap_clips: Any, tmp_path: Path
) -> None:
    """A studio audit's find: an extracted folder whose archive SHA256SUMS lists was
    recorded in the manifest and the model card as that archive's sha256 (files taken out
    of the folder or not); each source is now recorded as what was read: a folder by its
    name (not a local path) and the sha256 of its files' list."""
    from trainer.data.build import build_dataset
    from trainer.export import recorded_source
    from trainer.model_card import render

    result, models = trained
    manifest = load_manifest(models)
    origins = result.splits.train.meta["archives"]
    assert [recorded_source(o) for o in origins] == manifest.provenance.data
    for entry, origin in zip(manifest.provenance.data, origins, strict=True):
        assert entry["kind"] == "folder" and entry["sha256"] == origin["files_sha256"]
        assert not Path(entry["name"]).is_absolute() and "archive" not in entry
    root = tmp_path / "mocap"
    shutil.copytree(mocap_clips.root, root)
    listed = "0" * 64  # the archive's sum as SHA256SUMS gives it; the archive is absent
    (root / "SHA256SUMS").write_text(f"{listed}  bandai-namco-research-motiondataset.tar.xz\n")
    build_dataset(root, tmp_path / "poses.npz", seed=0, workers=1, progress=False)
    origins = load_dataset(tmp_path / "poses.npz").meta["archives"]
    (bandai,) = [o for o in origins if o["source"] == "bandai-namco"]
    assert bandai["sha256"] == listed and bandai["verified"] is False  # the dataset's meta
    entry = recorded_source(bandai)
    assert entry["sha256"] == bandai["files_sha256"] != listed, entry
    assert entry["archive"] == "bandai-namco-research-motiondataset.tar.xz"
    card = render(manifest.model_copy(update={"provenance": manifest.provenance.model_copy(
        update={"data": [entry]})}))  # fmt: skip
    assert f"extracted from `{entry['archive']}`, not checked against it" in card
    assert listed not in card


def test_onnx_matches_torch_on_real_poses(trained: tuple[Trained, Path]) -> None:
    result, models = trained
    poses = flat(result.splits.test.positions[:300])
    session = ort.InferenceSession(str(models / "encoder.onnx"), providers=["CPUExecutionProvider"])
    (z_ort,) = session.run(None, {"pose": poses.numpy()})
    with torch.no_grad():
        z_torch = result.ae.encode(poses).numpy()
    assert np.abs(z_ort - z_torch).max() <= 1e-5
    decoder = ort.InferenceSession(str(models / "decoder.onnx"), providers=["CPUExecutionProvider"])
    (x_ort,) = decoder.run(None, {"latent": z_torch})
    with torch.no_grad():
        x_torch = result.ae.decode(torch.from_numpy(z_torch)).numpy()
    assert np.abs(x_ort - x_torch).max() <= 1e-5
    solver = ort.InferenceSession(
        str(models / "solver_left_ankle+right_ankle.onnx"), providers=["CPUExecutionProvider"]
    )
    cols = [3 * JOINT_INDEX[j] + k for j in ("left_ankle", "right_ankle") for k in range(3)]
    targets = poses.numpy()[::-1, cols].copy()
    (z2,) = solver.run(None, {"latent": z_torch, "targets": targets})
    bank = result.bank
    s = bank.sets.index(["left_ankle", "right_ankle"])
    with torch.no_grad():
        want = bank(
            torch.from_numpy(z_torch)[None].expand(len(bank.sets), -1, -1),
            torch.from_numpy(poses.numpy()[::-1].copy())[None].expand(len(bank.sets), -1, -1),
        )[s].numpy()
    assert np.abs(z2 - want).max() <= 1e-5


def test_long_sets_train_apart_and_answer_as_their_own_bank(
    trained: tuple[Trained, Path],
) -> None:
    """``solver.long_sets`` train in a bank of their own for ``long_epochs`` (stage
    ``solvers_long``); the merged bank answers, per solver, exactly as its own bank."""
    result, _ = trained
    assert result.states["solvers"].epoch == 1 and result.states["solvers_long"].epoch == 2
    assert result.bank.sets[-1] == ["head", "left_wrist", "right_wrist"]
    torch.manual_seed(3)
    norm = result.bank.norm
    a = SolverBank(norm, [["left_wrist"], ["left_ankle", "right_ankle"]], 8, [16, 16], True)
    b = SolverBank(norm, [["head", "left_wrist", "right_wrist", "left_ankle"]], 8, [16, 16], True)
    merged = merge_banks(a, b)
    z = torch.randn(5, 8)
    pose = flat(result.splits.test.positions[:5])
    for m, (bank, i) in enumerate([(a, 0), (a, 1), (b, 0)]):
        cols = target_columns(bank.sets[i])
        with torch.no_grad():
            want = SingleSolver(bank, i)(z, pose[:, cols])
            got = SingleSolver(merged, m)(z, pose[:, cols])
            batched = merged(z[None].expand(3, -1, -1), pose[None].expand(3, -1, -1))[m]
        assert torch.equal(got, want)
        torch.testing.assert_close(batched, want, atol=1e-6, rtol=0)
    with pytest.raises(ValueError, match="differ"):
        merge_banks(a, SolverBank(norm, [["head"]], 8, [32, 16], True))
    with pytest.raises(ValueError, match="both sets and long_sets"):
        load_config(None, {"solver": {"sets": [["head"]], "long_sets": [["head"]]}})
    # each bank's checkpoint tag reads only its own sets and epochs
    base = {"sets": [["head"]], "long_sets": [["left_wrist", "right_wrist"]]}
    cfg = load_config(None, {"solver": base})
    more = load_config(None, {"solver": {**base, "long_epochs": 3}})
    other = load_config(None, {"solver": {**base, "sets": [["pelvis"]], "epochs": 2}})
    assert config_tag(cfg, "solvers") == config_tag(more, "solvers")
    assert config_tag(cfg, "solvers_long") != config_tag(more, "solvers_long")
    assert config_tag(cfg, "solvers_long") == config_tag(other, "solvers_long")
    assert config_tag(cfg, "solvers") != config_tag(other, "solvers")


@pytest.mark.parametrize("mode", ["plain", "delta", "anchored"])
def test_lean_fused_graph_answers_as_the_reference(
    trained: tuple[Trained, Path], mode: str
) -> None:
    """The exported fused graph (folded normalisation, solver and decoder run once on a
    doubled batch) answers as the readable composition of the trainer's own modules."""
    result, models = trained
    poses = flat(result.splits.test.positions[:300])
    joints = ["left_ankle", "right_ankle"]
    solver = SingleSolver(result.bank, result.bank.sets.index(joints)).eval()
    cols = [3 * JOINT_INDEX[j] + k for j in joints for k in range(3)]
    targets = poses[torch.arange(len(poses) - 1, -1, -1)][:, cols]
    with torch.no_grad():
        want = FusedGraph(result.ae, solver, joints, mode)(poses, targets)
        got = LeanFusedGraph(result.ae, solver, joints, mode)(poses, targets)
    assert float((got - want).abs().max()) <= 2e-5
    assert float((want - poses).abs().max()) > 1e-3  # the edit moves the pose
    if mode == "anchored":  # what the tiny run exported
        session = ort.InferenceSession(
            str(models / "fused_left_ankle+right_ankle.onnx"), providers=["CPUExecutionProvider"]
        )
        (onnx_out,) = session.run(None, {"pose": poses.numpy(), "targets": targets.numpy()})
        assert np.abs(onnx_out - want.numpy()).max() <= 2e-5


def test_tied_weights_are_really_tied(small_dataset: Path) -> None:
    poses = flat(load_dataset(small_dataset).positions[:512])
    ae = TiedAutoencoder(Normaliser(*feature_stats(poses, 0.01)), [200, 200], 64)
    # three weight matrices shared by encoder and decoder, nothing else but biases
    shapes = sorted(tuple(p.shape) for p in ae.weights)
    assert shapes == [(64, 200), (200, 63), (200, 200)]
    n_params = sum(p.numel() for p in ae.parameters())
    assert n_params == 63 * 200 + 200 * 200 + 200 * 64 + (200 + 200 + 64) + (63 + 200 + 200)
    z = ae.encode(poses[:4]).detach()
    before = ae.decode(z).detach()
    with torch.no_grad():
        ae.weights[0].mul_(1.5)  # an encoder weight: the decoder must see the change
    assert not torch.allclose(ae.decode(z), before)
    # gradients of the decoder flow into the shared matrices
    ae.zero_grad()
    ae.decode(z).sum().backward()
    assert ae.weights[0].grad is not None and ae.weights[0].grad.abs().sum() > 0


def test_normalisation_stats_never_change(trained: tuple[Trained, Path]) -> None:
    result, _ = trained
    ae = result.ae
    mean, std = ae.norm.mean.clone(), ae.norm.std.clone()
    poses = flat(result.splits.val.positions[:64])
    first = ae(poses).detach()
    for _ in range(200):
        ae(poses)
    ae.train()
    ae(poses)
    ae.eval()
    assert torch.equal(ae.norm.mean, mean) and torch.equal(ae.norm.std, std)
    assert torch.equal(ae(poses).detach(), first)
    # a feature with no spread (the canonical pelvis x/z is always 0) is floored, not 0
    assert float(std.min()) >= np.float32(0.01)


def test_tampered_model_file_is_rejected(trained: tuple[Trained, Path], tmp_path: Path) -> None:
    _, models = trained
    copy = tmp_path / "models"
    shutil.copytree(models, copy)
    load_manifest(copy)  # intact: fine
    target = copy / "solver_left_wrist.onnx"
    data = bytearray(target.read_bytes())
    data[len(data) // 2] ^= 0xFF
    target.write_bytes(bytes(data))
    with pytest.raises(ManifestError, match=r"solver_left_wrist\.onnx.*sha256"):
        load_manifest(copy)
    target.unlink()
    with pytest.raises(ManifestError, match="model file missing"):
        load_manifest(copy)


def test_tampered_manifest_is_rejected(trained: tuple[Trained, Path], tmp_path: Path) -> None:
    _, models = trained
    copy = tmp_path / "models"
    shutil.copytree(models, copy)
    raw = json.loads((copy / "manifest.json").read_text())
    raw["skeleton"]["joints"][0], raw["skeleton"]["joints"][1] = "spine1", "pelvis"
    (copy / "manifest.json").write_text(json.dumps(raw))
    with pytest.raises(ManifestError, match="canonical skeleton"):
        load_manifest(copy)
    (copy / "manifest.json").write_text("{not json")
    with pytest.raises(ManifestError, match="not readable JSON"):
        load_manifest(copy)
    # the turn search's completion critic needs completion level 1
    raw = json.loads((models / "manifest.json").read_text())
    raw["serving"].update(turn_yaws=12, turn_critic="completion")
    raw["models"] = [m for m in raw["models"] if m["kind"] != "completion"]
    (copy / "manifest.json").write_text(json.dumps(raw))
    with pytest.raises(ManifestError, match="turn_critic = completion needs completion"):
        load_manifest(copy, verify=False)


def _state(result: Trained) -> dict[str, torch.Tensor]:
    out = {f"ae.{k}": v for k, v in result.ae.state_dict().items()}
    out.update({f"bank.{k}": v for k, v in result.bank.state_dict().items()})
    for i, net in enumerate(result.completion):
        out.update({f"c{i}.{k}": v for k, v in net.state_dict().items()})
    return out


@pytest.mark.slow
def test_same_seed_same_models_and_resume_is_exact(
    small_dataset: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    a = train_all(tiny_config(small_dataset, tmp_path / "a", tmp_path / "ma"), fresh=True)
    b = train_all(tiny_config(small_dataset, tmp_path / "b", tmp_path / "mb"), fresh=True)
    sa, sb = _state(a), _state(b)
    assert all(torch.equal(sa[k], sb[k]) for k in sa)
    # interrupted after one AE epoch (at its checkpoint), then resumed to two: equals two
    # epochs straight, the latents shaken too (their noise drawn on resuming as it was)
    two = {"autoencoder": {"epochs": 2, "latent_noise": 0.1}}
    straight = train_all(
        tiny_config(small_dataset, tmp_path / "c", tmp_path / "mc", **two), fresh=True
    )
    save = stages.save_checkpoint

    def save_then_stop(*args: Any, **kwargs: Any) -> None:
        save(*args, **kwargs)
        raise KeyboardInterrupt

    monkeypatch.setattr(stages, "save_checkpoint", save_then_stop)
    with pytest.raises(KeyboardInterrupt):
        train_all(tiny_config(small_dataset, tmp_path / "d", tmp_path / "md", **two), fresh=True)
    monkeypatch.setattr(stages, "save_checkpoint", save)
    resumed = train_all(tiny_config(small_dataset, tmp_path / "d", tmp_path / "md", **two))
    assert resumed.states["autoencoder"].epoch == 2
    s1, s2 = _state(straight), _state(resumed)
    assert all(torch.equal(s1[k], s2[k]) for k in s1), "resume diverged from a straight run"
    # a different seed gives different weights
    other = train_all(
        tiny_config(small_dataset, tmp_path / "e", tmp_path / "me", seed=1), fresh=True
    )
    assert not torch.equal(_state(other)["ae.weights.0"], sa["ae.weights.0"])


@pytest.mark.slow
def test_ddp_two_processes_end_with_equal_weights(small_dataset: Path, tmp_path: Path) -> None:
    cfg_path = tmp_path / "tiny.toml"
    lines = [
        f'dataset = "{small_dataset}"',
        f'run_dir = "{tmp_path / "run"}"',
        f'out_dir = "{tmp_path / "models"}"',
        "threads = 1",
        "max_train_frames = 3000",
        "max_eval_frames = 300",
        "[autoencoder]\nepochs = 1",
        '[solver]\nepochs = 1\nsets = [["left_wrist"]]',
        "[completion]\nepochs = 1\nhidden = [32]\n"
        'schemes = [["pelvis", "neck", "left_wrist", "right_wrist", "left_ankle", "right_ankle"]]',
    ]
    cfg_path.write_text("\n".join(lines) + "\n")
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.run(
        [
            sys.executable, "-m", "torch.distributed.run", "--standalone",
            "--nproc_per_node", "2", "-m", "trainer.cli", "train",
            "--config", str(cfg_path), "--no-export",
        ],
        capture_output=True, text=True, timeout=300, env=env, cwd=REPO,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    # both ranks write to one pipe, so their lines may run together: match, do not split
    found = re.findall(r"weights digest rank (\d+): ([0-9a-f]{64})", proc.stdout + proc.stderr)
    digests = dict(found)
    assert set(digests) == {"0", "1"}, proc.stderr[-2000:]
    assert digests["0"] == digests["1"]
    assert (tmp_path / "run" / "autoencoder.pt").exists()  # rank 0 wrote its checkpoint


def test_model_card_lists_every_model(trained: tuple[Trained, Path]) -> None:
    _, models = trained
    card = (models / "README.md").read_text()
    manifest = load_manifest(models)
    assert manifest.version in card
    assert "non-commercial" in card
    for entry in manifest.models:
        assert f"| {entry.name} | {entry.parameters:,} |" in card


def test_completion_loss_mpjpe_is_the_mean_joint_distance(trained: tuple[Trained, Path]) -> None:
    """``completion.loss = "mpjpe"`` trains on the figure the benchmarks score (the mean
    per-joint distance of real poses), ``mse`` on the squared coordinates; only a loss other
    than the default enters the completion checkpoints' tag (older runs stay valid)."""
    result, _ = trained
    true = flat(result.splits.test.positions[:64])
    pred = true.roll(1, dims=0)  # other real poses: errors of every size
    got = completion_loss(pred, true, "mpjpe")
    assert float(got) * 100.0 == pytest.approx(mpjpe_cm(pred, true), rel=1e-6)
    assert float(completion_loss(pred, true, "mse")) == pytest.approx(
        float(((pred - true) ** 2).mean()), rel=1e-6
    )
    mse = load_config(None, {"completion": {"loss": "mse"}})
    mpjpe = load_config(None, {"completion": {"loss": "mpjpe"}})
    assert config_tag(mse, "completion1") == config_tag(load_config(None, {}), "completion1")
    assert config_tag(mpjpe, "completion1") != config_tag(mse, "completion1")
    assert config_tag(mpjpe, "solvers") == config_tag(mse, "solvers")


@pytest.mark.parametrize("distance", [False, True])
def test_solver_joint_terms_measure_what_they_say(
    trained: tuple[Trained, Path], distance: bool
) -> None:
    """``solver.joint_loss``: the target and stay terms are the MSE of the target columns /
    of the other joints' moves, or (``distance``) the mean per-joint distances, on real
    pairs; only the non-default choice enters the solvers' checkpoint tag."""
    result, _ = trained
    ae, bank = result.ae, result.bank
    poses = flat(result.splits.test.positions[:48])
    start, goal = poses[:24], poses[24:]
    with torch.no_grad():
        target, answers = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain",
                                        0.0, False, distance)  # fmt: skip
        both, _ = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain", 1.0, False,
                                distance)  # fmt: skip
    for s, joints in enumerate(bank.sets):
        idx = [JOINT_INDEX[j] for j in joints]
        rest = [j for j in range(21) if j not in idx]
        diff = (answers[s] - goal).reshape(len(goal), 21, 3)
        moved = (answers[s] - start).reshape(len(goal), 21, 3)
        if distance:
            want_t = diff[:, idx].norm(dim=-1).mean()
            want_s = moved[:, rest].norm(dim=-1).mean()
        else:
            want_t = (diff[:, idx] ** 2).mean()
            want_s = (moved[:, rest] ** 2).mean()
        torch.testing.assert_close(target[s], want_t, rtol=1e-5, atol=0)
        torch.testing.assert_close(both[s] - target[s], want_s, rtol=1e-4, atol=0)
    tags = {
        config_tag(load_config(None, {"solver": {"joint_loss": k}}), "solvers")
        for k in ("mse", "distance")
    }
    assert config_tag(load_config(None, {}), "solvers") in tags and len(tags) == 2


def test_version_names_the_files_and_the_serving(trained: tuple[Trained, Path]) -> None:
    """Two exports of the same networks served differently (completion views) are two
    versions; the same files and serving, one."""
    _, models = trained
    manifest = load_manifest(models)
    viewed = manifest.serving.model_copy(update={"completion_yaws": 4})
    assert model_version(manifest.models, manifest.serving) == manifest.version
    assert model_version(manifest.models, viewed) != manifest.version


def test_latent_noise_shakes_a_second_copy_and_retrains_what_reads_the_latent(
    small_dataset: Path,
) -> None:
    """``autoencoder.latent_noise``: the round trip gives the clean reconstructions, then
    those decoded from latents shaken in proportion to each dimension's batch std (more
    noise, farther), drawn from the generator given, so a run is repeatable. Off, it is not
    in any tag (checkpoints from before the option keep theirs); on, it retrains the
    autoencoder and the solvers, not the completion levels."""
    poses = flat(load_dataset(small_dataset).positions[:256])
    torch.manual_seed(0)
    ae = TiedAutoencoder(Normaliser(*feature_stats(poses, 0.01)), [200, 200], 64)
    with torch.no_grad():
        clean = ae(poses)
        shaken = {s: ae(poses, s, torch.Generator().manual_seed(1)) for s in (0.1, 0.3)}
        again = ae(poses, 0.1, torch.Generator().manual_seed(1))
    assert shaken[0.1].shape == (512, 63) and torch.equal(again, shaken[0.1])
    assert torch.allclose(shaken[0.1][:256], clean, atol=1e-6)
    moved = {s: float((out[256:] - clean).norm(dim=1).mean()) for s, out in shaken.items()}
    assert 0 < moved[0.1] < moved[0.3]
    off = load_config(None, {"autoencoder": {"latent_noise": 0.0}})
    on = load_config(None, {"autoencoder": {"latent_noise": 0.1}})
    assert "latent_noise" not in _section(off, "autoencoder")
    assert _section(on, "autoencoder")["latent_noise"] == 0.1
    for stage in ("autoencoder", "solvers", "solvers_long", "completion1"):
        changes = config_tag(on, stage) != config_tag(off, stage)
        assert changes == (not stage.startswith("completion")), stage


@pytest.mark.parametrize(("single", "per_set"), [("other_weight", "other_weights"),
                                                 ("stay_weight", "stay_weights")])  # fmt: skip
def test_per_set_weights_weigh_each_set_of_the_shared_bank_alone(
    trained: tuple[Trained, Path], small_dataset: Path, tmp_path: Path, single: str, per_set: str
) -> None:
    """``solver.other_weights`` / ``solver.stay_weights``: a set named there trains exactly,
    bit for bit, as in a bank whose every set has that weight, the others as with
    ``other_weight`` / ``stay_weight`` (each set's solver is trained on its own loss alone);
    unset it is in no tag, set it retrains the shared bank only; a key that is no set's key
    (an unknown joint, joints out of order) is refused."""
    result, _ = trained
    d = init_distributed()
    total = float(reference_lengths(result.splits.train).sum())

    def bank(name: str, **solver: Any) -> list[torch.Tensor]:
        cfg = tiny_config(small_dataset, tmp_path / name, tmp_path / "models", solver=solver)
        trained_bank, _ = train_solvers(cfg, d, result.ae, result.splits, total, fresh=True)
        return [p.detach() for n, p in trained_bank.named_parameters() if not n.startswith("norm.")]

    low, high = bank("low", **{single: 0.01}), bank("high", **{single: 1.0})
    mixed = bank("mixed", **{single: 0.01, per_set: {"left_ankle+right_ankle": 1.0}})
    assert len(mixed) == len(low) and all(len(p) == 2 for p in mixed)  # [S, ...] each
    assert not all(torch.equal(a[1], b[1]) for a, b in zip(low, high, strict=True))
    for m, lo, hi in zip(mixed, low, high, strict=True):
        assert torch.equal(m[0], lo[0]) and torch.equal(m[1], hi[1])
    base = load_config(None, {})
    assert per_set not in _section(base, "solver")
    own = load_config(None, {"solver": {per_set: {"left_knee": 0.3}}})
    for stage in ("autoencoder", "solvers", "solvers_long", "completion1"):
        assert (config_tag(own, stage) != config_tag(base, stage)) == (stage == "solvers")
    # the tags hash the weights trained with, not how they are written: a key of no set
    # trained, a weight equal to the single one (the long bank's other weight equal to it)
    same = {"left_knee": getattr(base.solver, single), "neck": 0.3, "left_wrist+neck": 0.3}
    extras: list[dict[str, Any]] = [{per_set: same}]
    if single == "other_weight":
        extras.append({"long_other_weight": base.solver.other_weight})
    for extra in extras:
        for stage in ("solvers", "solvers_long"):
            assert config_tag(load_config(None, {"solver": extra}), stage) == config_tag(
                base, stage
            )
    typo = load_config(None, {"solver": {per_set: {"left_elbow+right_elbow": 0.3, "head": 0.2}}})
    assert typo.solver.unused_weights() == [f"{per_set}.left_elbow+right_elbow"]  # warned of
    with pytest.raises(ValueError, match=r"unknown joints \['left_wirst'\]"):
        load_config(None, {"solver": {per_set: {"left_wirst": 0.3}}})
    with pytest.raises(ValueError, match=f"{per_set}: 'right_wrist\\+left_wrist' is not a set's"):
        load_config(None, {"solver": {per_set: {"right_wrist+left_wrist": 0.3}}})


def test_stay_frames_measure_each_set_of_the_shared_bank_alone(
    trained: tuple[Trained, Path], small_dataset: Path, tmp_path: Path
) -> None:
    """``solver.stay_frames``: a set named there trains exactly, bit for bit, as in a bank
    whose every set's stay term is in that frame, the others as with ``stay_frame``; unset
    or equal to ``stay_frame`` it is in no tag, set it retrains the shared bank only; a key
    of no set is warned of, one that is no set's key refused, a frame not known refused."""
    result, _ = trained
    d = init_distributed()
    total = float(reference_lengths(result.splits.train).sum())

    def bank(name: str, **solver: Any) -> list[torch.Tensor]:
        cfg = tiny_config(small_dataset, tmp_path / name, tmp_path / "models",
                          solver={"stay_weight": 1.0, **solver})  # fmt: skip
        trained_bank, _ = train_solvers(cfg, d, result.ae, result.splits, total, fresh=True)
        return [p.detach() for n, p in trained_bank.named_parameters() if not n.startswith("norm.")]

    world, local = bank("world"), bank("local", stay_frame="local")
    mixed = bank("mixed", stay_frames={"left_wrist": "local"})  # sets: left_wrist, ankles
    assert not all(torch.equal(a[0], b[0]) for a, b in zip(world, local, strict=True))
    for m, w, lo in zip(mixed, world, local, strict=True):
        assert torch.equal(m[0], lo[0]) and torch.equal(m[1], w[1])
    base = load_config(None, {})
    assert "stay_frames" not in _section(base, "solver")
    own = load_config(None, {"solver": {"stay_frames": {"left_elbow": "local"}}})
    for stage in ("autoencoder", "solvers", "solvers_long", "completion1"):
        assert (config_tag(own, stage) != config_tag(base, stage)) == (stage == "solvers")
    same = load_config(None, {"solver": {"stay_frames": {"left_elbow": "world", "neck": "local"}}})
    assert config_tag(same, "solvers") == config_tag(base, "solvers")
    assert same.solver.unused_weights() == ["stay_frames.neck"]
    with pytest.raises(ValueError, match="stay_frames: 'right_wrist\\+left_wrist' is not a set's"):
        load_config(None, {"solver": {"stay_frames": {"right_wrist+left_wrist": "local"}}})
    with pytest.raises(ValueError, match="stay_frames"):
        load_config(None, {"solver": {"stay_frames": {"left_elbow": "parent"}}})


def test_stay_term_in_the_local_frame_measures_offsets_from_parents(
    trained: tuple[Trained, Path],
) -> None:
    """``solver.stay_frame = "local"``: the stay term is the MSE of the moves of the other
    joints' offsets from their parents (the root's position), on real pairs; a pose moved
    as a whole costs only its root's move; only the non-default choice enters the solvers'
    checkpoint tag."""
    result, _ = trained
    ae, bank = result.ae, result.bank
    poses = flat(result.splits.test.positions[:48])
    start, goal = poses[:24], poses[24:]
    with torch.no_grad():
        target, answers = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain")
        both, _ = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain", 1.0,
                                stay_frame="local")  # fmt: skip
    offsets = parent_offsets_t(answers) - parent_offsets_t(start).unsqueeze(0)
    for s, joints in enumerate(bank.sets):
        rest = [j for j in range(21) if j not in [JOINT_INDEX[n] for n in joints]]
        want = (offsets[s].reshape(len(goal), 21, 3)[:, rest] ** 2).mean()
        torch.testing.assert_close(both[s] - target[s], want, rtol=1e-4, atol=0)
    shifted = start + torch.tensor([0.1, 0.0, 0.0]).repeat(21)
    moved = (parent_offsets_t(shifted) - parent_offsets_t(start)).reshape(-1, 21, 3)
    assert torch.count_nonzero(moved.abs() > 1e-6) == len(start)  # the root's x only
    assert config_tag(load_config(None, {"solver": {"stay_frame": "world"}}), "solvers") == (
        config_tag(load_config(None, {}), "solvers")
    )
    local = load_config(None, {"solver": {"stay_frame": "local"}})
    assert config_tag(local, "solvers") != config_tag(load_config(None, {}), "solvers")
    assert config_tag(local, "completion1") == config_tag(load_config(None, {}), "completion1")


def test_stay_term_across_the_pelvis_lets_a_body_travel_as_a_whole(
    trained: tuple[Trained, Path],
) -> None:
    """``solver.stay_frame = "across"``: the stay term is the MSE of the other joints' moves
    relative to the pelvis across (x, z), on real pairs: a pose moved across as a whole
    costs nothing, one moved up costs its every joint's rise; a checkpoint tag of its own."""
    result, _ = trained
    ae, bank = result.ae, result.bank
    poses = flat(result.splits.test.positions[:48])
    start, goal = poses[:24], poses[24:]
    with torch.no_grad():
        target, answers = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain")
        both, _ = solver_losses(ae, bank, bank, start, goal, 0.0, 0.0, "plain", 1.0,
                                stay_frame="across")  # fmt: skip

    def on_pelvis(x: torch.Tensor) -> torch.Tensor:  # joints minus the pelvis's (x, 0, z)
        joints = x.reshape(*x.shape[:-1], 21, 3)
        return (joints - joints[..., :1, :] * torch.tensor([1.0, 0.0, 1.0])).reshape(x.shape)

    moves = on_pelvis(answers) - on_pelvis(start).unsqueeze(0)
    for s, joints in enumerate(bank.sets):
        rest = [j for j in range(21) if j not in [JOINT_INDEX[n] for n in joints]]
        want = (moves[s].reshape(len(goal), 21, 3)[:, rest] ** 2).mean()
        torch.testing.assert_close(both[s] - target[s], want, rtol=1e-4, atol=0)
    across = start + torch.tensor([0.3, 0.0, -0.2]).repeat(21)
    up = start + torch.tensor([0.0, 0.1, 0.0]).repeat(21)
    torch.testing.assert_close(across_pelvis_t(across), across_pelvis_t(start))
    rise = (across_pelvis_t(up) - across_pelvis_t(start)).reshape(-1, 21, 3)
    torch.testing.assert_close(rise[..., 1], torch.full_like(rise[..., 1], 0.1))
    assert float(rise[..., [0, 2]].abs().max()) < 1e-6
    tags = {f: config_tag(load_config(None, {"solver": {"stay_frame": f}}), "solvers")
            for f in ("world", "local", "across")}  # fmt: skip
    assert len(set(tags.values())) == 3


def test_every_stage_records_the_host_that_trained_it(
    trained: tuple[Trained, Path], small_dataset: Path
) -> None:
    """The same seed on another CPU gives slightly other weights, so the manifest names the
    host (CPU model, SIMD level, torch, threads) of every stage, and the model card too."""
    result, models = trained
    manifest = load_manifest(models)
    assert set(manifest.provenance.training_hosts) == set(result.states)
    assert all(hosts == [host()] for hosts in manifest.provenance.training_hosts.values())
    assert torch.backends.cpu.get_cpu_capability() in host()
    assert f"Trained on: {host()}." in (models / "README.md").read_text()
    assert manifest.provenance.dataset["file_sha256"] == sha256_file(small_dataset)


def test_train_says_in_one_line_what_is_wrong_with_its_config_or_data(
    small_dataset: Path, tmp_path: Path
) -> None:
    """A config mistake ended in a 50-70-line traceback, and a dataset whose split left
    val empty (2 clips of one content) failed deep in training ("cannot reshape array of
    size 0"): now one line that says what and where, exit code 1, nothing trained."""
    from typer.testing import CliRunner

    from trainer.cli import app

    runner = CliRunner()
    typo = tmp_path / "typo.toml"
    typo.write_text("[autoencoder]\nepoch = 1\n")
    r = runner.invoke(app, ["train", "--config", str(typo), "--run-dir", str(tmp_path / "run")])
    assert r.exit_code == 1 and "Traceback" not in r.output
    # the file and the key named, the near setting offered (was pydantic's 4-line text)
    assert f"{typo}: autoencoder.epoch: not a setting (did you mean 'epochs'?)" in r.output
    far = tmp_path / "far.toml"
    far.write_text('extends = "trainer/configs/default.toml"\n')  # relative to far.toml
    r = runner.invoke(app, ["train", "--config", str(far), "--run-dir", str(tmp_path / "run")])
    want = f"{tmp_path}/trainer/configs/default.toml: no such config file (extends = in {far}"
    assert r.exit_code == 1 and want in r.output.replace("\n", ""), r.output
    with np.load(small_dataset, allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    arrays["clip_split"] = np.where(arrays["clip_split"] == "val", "test", arrays["clip_split"])
    no_val = tmp_path / "no_val.npz"
    np.savez(no_val, **arrays)
    args = ["train", "--dataset", str(no_val), "--run-dir", str(tmp_path / "run"),
            "--out", str(tmp_path / "models")]  # fmt: skip
    r = runner.invoke(app, args)
    assert r.exit_code == 1 and "no val frames" in r.output, r.output
    assert not (tmp_path / "models").exists()
    assert not (tmp_path / "run").exists()  # (a studio audit: an empty run folder was left)
    # without test frames every stage trained, then the evaluation failed with a traceback
    # ("cannot reshape array of size 0"): refused before training like the others
    with np.load(small_dataset, allow_pickle=False) as npz:
        split = npz["clip_split"]
    no_test = tmp_path / "no_test.npz"
    np.savez(no_test, **{**arrays, "clip_split": np.where(split == "test", "val", split)})
    r = runner.invoke(app, [*args[:1], "--dataset", str(no_test), *args[3:]])
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert "no test frames" in r.output and not (tmp_path / "run").exists(), r.output
    # a bone of length 0 (a map's two source joints coincide) trained every stage, then the
    # export failed with a pydantic traceback: refused before training, naming the bone
    flat_spine = arrays["positions"].copy()
    flat_spine[:, JOINT_INDEX["spine1"]] = flat_spine[:, JOINT_INDEX["pelvis"]]
    zero = tmp_path / "zero_bone.npz"
    np.savez(zero, **{**arrays, "clip_split": split, "positions": flat_spine})
    r = runner.invoke(app, [*args[:1], "--dataset", str(zero), *args[3:]])
    assert r.exit_code == 1 and "Traceback" not in r.output, r.output
    assert (
        "the train split's mean bone length is outside 1 mm - 2 m for spine1 (pelvis -> "
        "spine1) 0.0000 m"
    ) in r.output.replace("\n", "") and not (tmp_path / "run").exists(), r.output
    # a train split smaller than one batch trained nothing (losses 0) and was exported,
    # served as ready (a studio audit): now refused, naming the frames and the batch
    n = int((arrays["clip_split"][arrays["clip"]] == "train").sum())
    big = tmp_path / "big_batch.toml"
    big.write_text(f"[solver]\nbatch_size = {n + 1}\n")
    args = ["train", "--config", str(big), "--dataset", str(small_dataset), "--run-dir",
            str(tmp_path / "run2"), "--out", str(tmp_path / "models")]  # fmt: skip
    r = runner.invoke(app, args)
    assert r.exit_code == 1, r.output
    assert f"train split has {n} frames, fewer than one batch ([solver] batch_size" in r.output
    assert not (tmp_path / "models").exists() and not (tmp_path / "run2").exists()
