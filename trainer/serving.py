"""Set an exported model folder's serving block from a config, without retraining.

The serving settings (``core.manifest.Serving``) change answers but not the networks,
except where the solvers' losses saw them: ``carry`` with ``solver.carry_loss``,
``keep_ends`` with ``solver.ends_loss`` and ``keep_elbows`` with ``solver.elbows_loss`` (and
``ends_loss``); those, and ``body``, ``delta`` and ``anchor``, which the training decides,
stay as the models were trained. The new block gets a new version (it hashes the serving
block too), the provenance's config takes the new serving values, and
``provenance.serving_changes`` records the change.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

from core.manifest import (
    TRAINED_SERVING,
    Manifest,
    Serving,
    load_manifest,
    manifest_json,
    model_version,
    stamped,
    write_manifest,
)
from trainer.config import SERVING_SETTINGS, TrainConfig, seen_by_losses
from trainer.export import git_commit_of, serving_of
from trainer.model_card import write_model_card


def locked(trained: dict[str, Any]) -> set[str]:
    """The serving settings the models were trained for, by their training config's
    ``solver`` section ``trained``: those set by the training whatever the losses saw
    (``core.manifest.TRAINED_SERVING``) and those the losses saw."""
    return {*TRAINED_SERVING, *seen_by_losses(trained)}


#: Settings of a config that ``not_applied`` leaves out: where files are, not how to train.
_PLACES = frozenset({"dataset", "run_dir", "out_dir", "accept_implausible"})


def not_applied(cfg: TrainConfig, manifest: Manifest) -> list[str]:
    """The settings of ``cfg`` that differ from those the models were trained with (their
    ``provenance.config``) and are not serving settings, so were not applied, each as
    ``"autoencoder.epochs 20 (the models': 2)"`` (``pose-trainer serving`` ignored them
    without a word: a studio audit, D12). Settings the manifest does not record (added
    since) are left out."""
    trained = manifest.provenance.config
    serving = {("solver", k) for k in SERVING_SETTINGS} | {
        ("completion", "serving_yaws"),
        ("completion", "serving_mirror"),
    }
    out = []
    for key, value in cfg.model_dump(mode="json").items():
        if key in _PLACES or key not in trained:
            continue
        pairs = (
            [((key, k), v, trained[key][k]) for k, v in value.items() if k in trained[key]]
            if isinstance(value, dict) and isinstance(trained[key], dict)
            else [((key,), value, trained[key])]
        )
        for where, want, was in pairs:
            if want != was and where not in serving:
                out.append(f"{'.'.join(where)} {want!r} (the models': {was!r})")
    return out


def set_serving(cfg: TrainConfig, models_dir: Path) -> tuple[Manifest, dict[str, Any]]:
    """Write ``models_dir``'s manifest (and model card) with ``cfg``'s serving block; the
    manifest and the changes made (``{}``: already so, nothing written). ``ValueError``
    names a setting that cannot change without retraining."""
    manifest = load_manifest(models_dir, verify=True)
    new = serving_of(cfg)
    changed = {
        k: {"from": getattr(manifest.serving, k), "to": getattr(new, k)}
        for k in Serving.model_fields
        if getattr(manifest.serving, k) != getattr(new, k)
    }
    if not changed:
        return manifest, {}
    config = copy.deepcopy(manifest.provenance.config)
    bad = sorted(set(changed) & locked(config.get("solver", {})))
    if bad:
        raise ValueError(
            "the models were trained for these serving settings; retrain to change them: "
            + ", ".join(f"{k} {changed[k]['from']!r} -> {changed[k]['to']!r}" for k in bad)
        )
    for key in SERVING_SETTINGS:
        config.setdefault("solver", {})[key] = getattr(cfg.solver, key)
    config.setdefault("completion", {}).update(
        serving_yaws=cfg.completion.serving_yaws, serving_mirror=cfg.completion.serving_mirror
    )
    record = {"from": manifest.version, "changed": changed, "git_commit": git_commit_of(models_dir)}
    provenance = manifest.provenance.model_copy(
        update={"config": config, "serving_changes": [*manifest.provenance.serving_changes, record]}
    )
    out = manifest.model_copy(
        update={
            "serving": new,
            "version": model_version(manifest.models, new),
            "provenance": provenance,
        }
    )
    out = stamped(Manifest.model_validate(manifest_json(out)))
    write_manifest(models_dir, out)
    write_model_card(models_dir, out)
    return out, changed
