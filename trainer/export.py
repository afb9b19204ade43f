"""Evaluation on val/test, ONNX export with parity checks, and the manifest."""

from __future__ import annotations

import logging
import os
import platform
import re
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import onnxruntime as ort
import torch
from torch import nn

from core.io import sha256_file, write_atomic
from core.manifest import (
    SCHEMA_VERSION,
    Manifest,
    ModelEntry,
    Normalisation,
    Provenance,
    Serving,
    SkeletonSpec,
    TensorSpec,
    model_version,
    stamped,
    write_manifest,
)
from core.skeleton import BONES, FRAME, JOINT_NAMES, NUM_JOINTS, PARENT_NAMES, bone_lengths
from trainer.config import SERVING_SETTINGS, TrainConfig
from trainer.data.dataset import FPS
from trainer.fused import FusedGraph, LeanFusedGraph
from trainer.mirror import mirror_entries
from trainer.model_card import write_model_card
from trainer.models import SingleSolver, TiedAutoencoder, target_columns
from trainer.stages import dataset_sha256
from trainer.train import (
    PairSource,
    Trained,
    ae_samples,
    answer_mode,
    augment,
    completion_inputs,
    flat,
    mpjpe_cm,
    reference_lengths,
    solver_metrics,
)

PARITY_TOLERANCE = 1e-5


def recorded_source(origin: dict[str, Any]) -> dict[str, str]:
    """What the manifest says a source was read from (its ``provenance.data`` entry): an
    archive by its name and sha256 (``verified`` "false" where SHA256SUMS did not list
    it; ``sha256sums`` "absent" too where there was no SHA256SUMS); an extracted folder by
    its name and the sha256 of its files' list (``trainer.data.sources.folder_digest``),
    never by the sum of an archive that was not read (a folder with files taken out was
    recorded as the whole archive)."""
    if origin.get("kind") == "folder":
        entry = {
            "name": Path(str(origin.get("path", "?"))).name + "/",
            "sha256": str(origin.get("files_sha256", "not recorded")),
            "kind": "folder",
            "files": str(origin.get("files", "?")),
        }
        if origin.get("file"):
            entry["archive"] = str(origin["file"])  # the one SHA256SUMS names: not checked
        return entry
    entry = {"name": str(origin.get("file")), "sha256": str(origin.get("sha256", "not recorded"))}
    if origin.get("verified") is False:
        entry["verified"] = "false"
        if origin.get("sha256sums") == "absent":  # no SHA256SUMS beside it at all
            entry["sha256sums"] = "absent"
    return entry


#: A licence text that forbids commercial use, as it is spelt: "CC BY-NC 4.0", "CC BY NC",
#: "Attribution-NonCommercial 4.0 International", "non-commercial", "noncommercial use".
NON_COMMERCIAL = re.compile(r"non[\s_-]?commercial|\bby[\s_-]?nc\b", re.IGNORECASE)


def licence_of(meta: dict[str, Any]) -> str:
    """The terms the weights inherit: the licence each source trained on has in the
    dataset (its map's ``licence``; a source held out whole is not trained on). It was one
    text for every export: a studio's models, trained on its own data, were labelled with
    the shipped models' non-commercial licence."""
    licences: dict[str, str] = meta.get("licences", {})
    held: dict[str, list[str]] = meta.get("holdout", {})
    used = {s: t for s, t in sorted(licences.items()) if held.get(s) != ["**"]}
    if not used:
        return "not recorded: the dataset names no licence for its sources"
    terms = "; ".join(f"{s}: {t.strip() or 'no licence given (its map names none)'}"
                      for s, t in used.items())  # fmt: skip
    nc = any(NON_COMMERCIAL.search(t) for t in used.values())
    return (
        f"{'Non-commercial: ' if nc else ''}these weights inherit the terms of the motion "
        f"capture they were trained on ({terms}). See the model card (README.md)."
    )


class EncoderGraph(nn.Module):
    def __init__(self, ae: TiedAutoencoder) -> None:
        super().__init__()
        self.ae = ae

    def forward(self, pose: torch.Tensor) -> torch.Tensor:
        return self.ae.encode(pose)


class DecoderGraph(nn.Module):
    def __init__(self, ae: TiedAutoencoder) -> None:
        super().__init__()
        self.ae = ae

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        return self.ae.decode(latent)


def evaluate(cfg: TrainConfig, trained: Trained) -> dict[str, dict[str, dict[str, float]]]:
    """Metrics (cm) on val and test for every model: ``{model name: {split: {metric}}}``."""
    ae, bank = trained.ae, trained.bank
    out: dict[str, dict[str, dict[str, float]]] = {}
    max_gap = max(1, round(cfg.solver.max_gap_seconds * FPS))
    total = float(reference_lengths(trained.splits.train).sum())
    with torch.no_grad():
        for split in ("val", "test"):
            data = getattr(trained.splits, split)
            poses = flat(data.positions)
            rng = np.random.default_rng(cfg.seed + 100)
            if len(poses) > cfg.max_eval_frames:
                sel = np.sort(rng.choice(len(poses), cfg.max_eval_frames, replace=False))
                sub = poses[torch.from_numpy(sel)]
            else:
                sub = poses
            out.setdefault("autoencoder", {})[split] = {"mpjpe_cm": mpjpe_cm(ae(sub), sub)}
            bodies = ae_samples(sub, np.random.default_rng(cfg.seed + 104), cfg.augment, total)
            out["autoencoder"][split]["new_bodies_mpjpe_cm"] = mpjpe_cm(ae(bodies), bodies)
            src = PairSource.of(data, max_gap)
            a, p = src.fixed_pairs(cfg.seed + 101, cfg.max_eval_frames)
            start, goal = src.pairs(a, p, np.random.default_rng(cfg.seed + 103), cfg.augment, total)
            mode = answer_mode(cfg.solver.delta, cfg.solver.anchor)
            metrics_by_key = solver_metrics(ae, bank, start, goal, mode)
            for key, metrics in metrics_by_key.items():
                out.setdefault(f"solver:{key}", {})[split] = metrics
            aug = augment(sub, np.random.default_rng(cfg.seed + 102), True, True, cfg.augment)
            for level, net in enumerate(trained.completion, start=1):
                pred = net(completion_inputs(trained.completion, level, aug, None))
                out.setdefault(f"completion:{level}", {})[split] = {"mpjpe_cm": mpjpe_cm(pred, aug)}
    return out


class _NoTorchvision(logging.Filter):
    """torch's ONNX exporter warns, 4 lines per network, that torchvision (which the
    trainer never uses) is not installed: 140 of a quick run's 324 lines (a studio audit,
    D12). Those lines alone are dropped."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith("torchvision is not installed")


logging.getLogger("torch.onnx._internal.exporter._registration").addFilter(_NoTorchvision())


def _export(
    module: nn.Module,
    args: tuple[torch.Tensor, ...],
    input_names: list[str],
    output_name: str,
    path: Path,
    opset: int,
) -> None:
    module.eval()
    batch = torch.export.Dim("batch", min=1, max=1 << 20)
    arg_names = list(module.forward.__code__.co_varnames[1 : 1 + len(args)])
    dynamic = {n: {0: batch} for n in arg_names}
    with warnings.catch_warnings(), tempfile.TemporaryDirectory() as tmp:
        warnings.simplefilter("ignore")
        program = torch.onnx.export(
            module,
            args,
            input_names=input_names,
            output_names=[output_name],
            dynamic_shapes=dynamic,
            opset_version=opset,
            dynamo=True,
            verbose=False,
        )
        assert program is not None
        tmp_path = Path(tmp) / path.name
        program.save(str(tmp_path))
        model = onnx.load(str(tmp_path))
    written = {o.version for o in model.opset_import if o.domain in ("", "ai.onnx")}
    if written != {opset}:  # (the manifest names cfg.opset: never one the files lack)
        raise RuntimeError(f"{path.name}: exported as ONNX opset {written}, not {opset}")
    model.producer_name = "marionette-trainer"
    model.doc_string = ""
    for node in model.graph.node:  # the exporter's notes: source paths and line numbers
        del node.metadata_props[:]
    onnx.checker.check_model(model, full_check=True)
    write_atomic(path, model.SerializeToString())


def _parity(
    path: Path, module: nn.Module, feeds: dict[str, torch.Tensor], graphs: int = 1
) -> float:
    """Max |ORT - torch| on real inputs; raises if above the tolerance (``PARITY_TOLERANCE``
    per network the graph chains: a fused anchored edit runs five)."""
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    got = session.run(None, {k: v.numpy() for k, v in feeds.items()})[0]
    with torch.no_grad():
        want = module(*feeds.values()).numpy()
    err = float(np.abs(got - want).max())
    if not err <= PARITY_TOLERANCE * graphs:
        raise RuntimeError(
            f"{path.name}: ONNX/torch mismatch {err:.3g} > {PARITY_TOLERANCE * graphs:.3g}"
        )
    return err


def body_shapes(lengths: np.ndarray, min_share: float = 0.01, most: int = 16) -> list[list[float]]:
    """Distinct skeletons of the training frames ``[N, 20]``: frames grouped by their summed
    bone length to the centimetre; each group with >= ``min_share`` of the frames gives
    its mean bone lengths (largest groups first, at most ``most``)."""
    keys = np.round(lengths.sum(axis=1), 2)
    values, counts = np.unique(keys, return_counts=True)
    order = np.argsort(-counts)
    shapes = []
    for i in order[:most]:
        if counts[i] < min_share * len(lengths):
            continue
        shapes.append([round(float(v), 6) for v in lengths[keys == values[i]].mean(axis=0)])
    return shapes


def git_commit_of(out: Path) -> str:
    """HEAD of the repository this code runs from (not of the current directory: a studio
    exporting from its own repository recorded that one's), with ``-dirty`` if a tracked
    file other than the export's own (``out``) is modified; "unknown" outside one."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(
            ["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True, cwd=here
        ).stdout.strip()
        top = subprocess.run(
            ["git", "rev-parse", "--show-toplevel"], capture_output=True, text=True, check=True,
            cwd=here,
        ).stdout.strip()  # fmt: skip
        spec = ["--", top]
        if out.resolve().is_relative_to(Path(top).resolve()):
            spec.append(f":(exclude){out.resolve()}")
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", *spec],
            capture_output=True,
            text=True,
            check=True,
            cwd=here,
        ).stdout.strip()
        return head + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def serving_of(cfg: TrainConfig) -> Serving:
    """The manifest's serving block of models trained and served with ``cfg``."""
    return Serving(
        body="total_length" if cfg.augment.enabled and cfg.augment.normalise_size
        else "nearest_skeleton",
        delta=cfg.solver.delta,
        anchor=cfg.solver.delta and cfg.solver.anchor,
        **{k: getattr(cfg.solver, k) for k in SERVING_SETTINGS},
        completion_yaws=cfg.completion.serving_yaws,
        completion_mirror=cfg.completion.serving_mirror,
    )  # fmt: skip


def _params(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def export_all(
    cfg: TrainConfig,
    trained: Trained,
    metrics: dict[str, dict[str, dict[str, float]]],
    out_dir: Path | None = None,
) -> Manifest:
    """Export every network to ``out_dir`` and write the manifest: into a folder beside it,
    swapped into place once whole (:func:`_swap_into`), so that an interrupted export
    leaves the models that were there (it left new networks beside the old manifest:
    a folder the service refused), and no file of an older export stays behind."""
    final = Path(out_dir or cfg.out_dir)
    check_replaceable(final, Path(cfg.run_dir))
    _sweep(final, "partial")
    out = final.parent / f".{final.name}.partial-{os.getpid()}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    try:
        manifest = _export_into(cfg, trained, metrics, out, final)
        _swap_into(out, final)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    _sweep(final, "old")  # (only now: one may hold the last models, if final was lost)
    return manifest


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs on this host."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        return True
    return True


def _sweep(final: Path, kind: str) -> None:
    """Remove ``final``'s hidden ``.<name>.<kind>-<pid>`` siblings whose process is gone:
    an export killed part-way left its ``partial`` folder (or, between the renames, the
    ``old`` one) for good, hidden (a studio audit, D7: 28 MB each, full models)."""
    prefix = f".{final.name}.{kind}-"
    if not final.parent.is_dir():
        return
    for path in final.parent.iterdir():
        pid = path.name.removeprefix(prefix)
        ours = path.name.startswith(prefix) and pid.isdigit()
        if ours and not _alive(int(pid)) and path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)


def check_replaceable(final: Path, run_dir: Path | None = None) -> None:
    """Refuse an ``out_dir`` the export must not replace: a file, or a symbolic link (the
    swap renamed either aside to a hidden ``.<name>.old-<pid>``, where it stayed: the file
    lost from view, the link's deployment left stale; a studio audit, D2); a folder that
    holds files but is not a models folder; a folder that is, or holds, ``run_dir`` (the
    checkpoints would be replaced with it: it trained every stage, then the export failed
    with a traceback, D3). ``out_dir`` inside ``run_dir`` is fine (``train --quick``'s)."""
    if final.is_symlink():
        raise FileExistsError(
            f"{final}: a symbolic link (to {os.readlink(final)}), not a folder: the export "
            "replaces the models folder whole and would leave the link behind, renamed; "
            "give the folder itself, or a new path, as out_dir / --out"
        )
    if final.exists() and not final.is_dir():
        raise FileExistsError(
            f"{final}: a file, not a folder: the export would move it aside and replace it; "
            "give a new or empty folder, or a models folder to replace, as out_dir / --out"
        )
    if run_dir is not None:
        models, run = final.resolve(), run_dir.resolve()
        if run == models or models in run.parents:
            where = "is" if run == models else "is inside"
            raise FileExistsError(
                f"{final}: the run dir {run_dir} {where} it, and the export replaces this "
                "folder whole (the checkpoints with it): give run_dir / --run-dir and "
                "out_dir / --out separate folders"
            )
    if final.is_dir() and any(final.iterdir()) and not (final / "manifest.json").is_file():
        raise FileExistsError(
            f"{final}: the folder holds files but no manifest.json (not a models folder); "
            "export into a new or empty folder, or a models folder to replace"
        )


def _swap_into(new: Path, final: Path) -> None:
    """``new`` in place of ``final``: the old folder moved aside, the new one renamed in,
    the old one removed (if the process dies in between, the old models are in
    ``.<name>.old-<pid>`` beside it)."""
    old = final.parent / f".{final.name}.old-{os.getpid()}"
    if final.exists():
        shutil.rmtree(old, ignore_errors=True)
        final.rename(old)
    new.rename(final)
    shutil.rmtree(old, ignore_errors=True)


def _export_into(
    cfg: TrainConfig,
    trained: Trained,
    metrics: dict[str, dict[str, dict[str, float]]],
    out: Path,
    final: Path,
) -> Manifest:
    """:func:`export_all`'s work, into ``out`` (the folder to become ``final``)."""
    ae, bank = trained.ae, trained.bank
    val = flat(trained.splits.val.positions)
    sample = val[: min(len(val), 512)]
    latent = ae.latent_dim
    entries: list[ModelEntry] = []
    losses = {k: s.history[-1] for k, s in trained.states.items() if s.history}

    def add(
        name: str,
        file: str,
        module: nn.Module,
        feeds: dict[str, torch.Tensor],
        output: str,
        params: int,
        **extra: Any,
    ) -> None:
        path = out / file
        _export(module, tuple(feeds.values()), list(feeds), output, path, cfg.opset)
        # the graph answers as the module it came from (and as its readable reference)
        reference, graphs = extra.pop("reference", None), extra.pop("graphs", 1)
        _parity(path, module, feeds, graphs)
        if reference is not None:
            _parity(path, reference, feeds, graphs)
        with torch.no_grad():
            out_dim = module(*feeds.values()).shape[1]
        stage = extra.pop("stage")
        of = extra.pop("metrics_of", name)  # a fused graph reports its solver's metrics
        entries.append(
            ModelEntry(
                name=name,
                file=file,
                sha256=sha256_file(path),
                bytes=path.stat().st_size,
                parameters=params,
                inputs=[TensorSpec(name=k, shape=["batch", v.shape[1]]) for k, v in feeds.items()],
                outputs=[TensorSpec(name=output, shape=["batch", out_dim])],
                losses={k: float(v) for k, v in losses.get(stage, {}).items() if k != "epoch"},
                metrics={
                    f"{split}_{m}": v
                    for split, values in (
                        metrics.get(of) or metrics.get(of.split(":")[0], {})
                    ).items()
                    for m, v in values.items()
                },
                **extra,
            )
        )

    with torch.no_grad():
        z = ae.encode(sample)
    ae_params = _params(ae)
    add(
        "autoencoder",
        "encoder.onnx",
        EncoderGraph(ae),
        {"pose": sample},
        "latent",
        ae_params,
        kind="autoencoder",
        part="encoder",
        stage="autoencoder",
    )
    add(
        "autoencoder:decoder",
        "decoder.onnx",
        DecoderGraph(ae),
        {"latent": z},
        "pose",
        ae_params,
        kind="autoencoder",
        part="decoder",
        stage="autoencoder",
    )
    long = {tuple(sorted(j)) for j in cfg.solver.long_sets}
    for index, joints in enumerate(bank.sets):
        key = "+".join(sorted(joints))
        stage = "solvers_long" if tuple(sorted(joints)) in long else "solvers"
        solver = SingleSolver(bank, index).eval()
        feeds = {"latent": z, "targets": sample[:, target_columns(joints)]}
        add(
            f"solver:{key}",
            f"solver_{key}.onnx",
            solver,
            feeds,
            "solved_latent",
            _params(solver),
            kind="solver",
            joints=list(joints),
            key=key,
            stage=stage,
        )
        mode = answer_mode(cfg.solver.delta, cfg.solver.anchor)
        add(
            f"fused:{key}",
            f"fused_{key}.onnx",
            LeanFusedGraph(ae, solver, list(joints), mode).eval(),
            {"pose": sample, "targets": sample[:, target_columns(joints)]},
            "solved_pose",
            ae_params + _params(solver),
            kind="fused",
            joints=list(joints),
            key=key,
            stage=stage,
            metrics_of=f"solver:{key}",
            graphs=5,  # encoder, solver twice, decoder twice
            reference=FusedGraph(ae, solver, list(joints), mode).eval(),
        )
    aug = augment(sample, np.random.default_rng(0), True, True)
    for level, net in enumerate(trained.completion, start=1):
        keypoints = completion_inputs(trained.completion, level, aug, None)
        add(
            f"completion:{level}",
            f"completion_{level}.onnx",
            net,
            {"keypoints": keypoints},
            "pose",
            _params(net),
            kind="completion",
            joints=list(net.joints),
            level=level,
            stage=f"completion{level}",
        )

    # each set's edit and its mirror image in one graph (serving.solve_mirror), from the above
    entries += mirror_entries(out, {str(e.key): e for e in entries if e.kind == "fused"})

    train_poses = trained.splits.train.positions
    all_lengths = bone_lengths(train_poses.astype(np.float64))
    lengths = reference_lengths(trained.splits.train)
    skeletons = body_shapes(all_lengths)
    ref = {JOINT_NAMES[child]: round(float(lengths[i]), 6) for i, (child, _) in enumerate(BONES)}
    data_meta = dict(trained.splits.train.meta)
    archives = [recorded_source(a) for a in data_meta.get("archives", [])]
    serving = serving_of(cfg)
    manifest = Manifest(
        schema_version=SCHEMA_VERSION,
        version=model_version(entries, serving),
        licence=licence_of(data_meta),
        opset=cfg.opset,
        latent_dim=latent,
        skeleton=SkeletonSpec(
            joints=list(JOINT_NAMES),
            parents=[PARENT_NAMES[j] for j in JOINT_NAMES],
            reference_bone_lengths=ref,
            frame=dict(FRAME),
            skeletons=skeletons,
        ),
        normalisation=Normalisation(
            mean=[float(v) for v in ae.norm.mean],
            std=[float(v) for v in ae.norm.std],
            std_floor=cfg.autoencoder.std_floor,
        ),
        serving=serving,
        models=entries,
        provenance=Provenance(
            data=archives,
            dataset={
                **{k: v for k, v in data_meta.items() if k != "archives"},
                "file_sha256": dataset_sha256(cfg.dataset),  # the npz trained on (hashed once)
            },
            split_seed=int(data_meta.get("seed", 0)),
            config=cfg.model_dump(mode="json"),
            git_commit=git_commit_of(final),
            versions={
                "python": platform.python_version(),
                "torch": torch.__version__,
                "onnx": onnx.__version__,
                "onnxruntime": ort.__version__,
                "numpy": np.__version__,
            },
            training_seconds={k: round(s.seconds, 1) for k, s in trained.states.items()},
            training_hosts={k: s.hosts for k, s in trained.states.items()},
        ),
    )
    manifest = stamped(manifest)
    write_manifest(out, manifest)
    write_model_card(out, manifest)
    assert sample.shape[1] == NUM_JOINTS * 3
    return manifest
