"""Copy some networks of one models folder into another, files and manifest entries: an
ablation row that changed only the autoencoder or the solvers is scored with the shipped
completion levels (trainer/configs/ablation/quick_completion.toml trains them one epoch),
and a row's solvers of a few sets can be put beside the shipped rest.

    python scripts/swap_models.py --source models --into runs/ablation/X/models --kind completion
    python scripts/swap_models.py --source runs/ablation/X/models --into /tmp/m \\
        --key left_elbow --key right_elbow   # solver, fused and mirror graphs of those sets

The folder ``--into`` keeps its version: a scratch folder for `bench.heldout --models`, not a
release (a mirror graph holds a set's and its mirror set's networks: swap both sides)."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from core.manifest import load_manifest, write_manifest


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", type=Path, required=True, help="models folder to copy from")
    parser.add_argument("--into", type=Path, required=True, help="models folder to copy into")
    parser.add_argument("--kind", action="append", default=[], help="every entry of a kind")
    parser.add_argument("--key", action="append", default=[], help="a solver set's entries")
    args = parser.parse_args(argv)
    source, into = load_manifest(args.source), load_manifest(args.into)
    chosen = [e for e in source.models if e.kind in args.kind or (e.key and e.key in args.key)]
    missing = set(args.key) - {e.key for e in chosen}
    if missing or not chosen:
        parser.error(f"nothing in {args.source} for keys {sorted(missing)} / kinds {args.kind}")
    names = {e.name: e for e in chosen}
    if set(names) - {e.name for e in into.models}:
        parser.error(f"not in {args.into}: {sorted(set(names) - {e.name for e in into.models})}")
    for entry in chosen:
        shutil.copyfile(args.source / entry.file, args.into / entry.file)
    models = [names.get(e.name, e) for e in into.models]
    write_manifest(args.into, into.model_copy(update={"models": models}))
    load_manifest(args.into)  # every file checked against its entry
    print(f"{len(chosen)} networks copied into {args.into}: {sorted(names)}")


if __name__ == "__main__":
    main()
