"""The dataset's train / val / test / holdout split: by clip, stratified, seeded."""

from __future__ import annotations

import zlib
from collections import defaultdict
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

#: Default split fractions (train, val, test).
SPLIT_FRACTIONS: dict[str, float] = {"train": 0.90, "val": 0.05, "test": 0.05}


def assign_splits(
    names: Sequence[str],
    sources: Sequence[str],
    contents: Sequence[str],
    seed: int,
    fractions: dict[str, float] | None = None,
    *,
    actors: Sequence[str] | None = None,
    fixed: Sequence[str] | None = None,
) -> npt.NDArray[np.str_]:
    """Split clips by clip, stratified by (source, content, actor), deterministic from
    ``seed``. A clip whose ``fixed`` entry is a split name (``holdout``, or a split a map
    forces) goes there and takes no part in the strata; ``holdout`` is never assigned
    otherwise.

    Per stratum of n clips (shuffled by a generator seeded with ``seed`` and the stratum):
    n = 1 -> test; n = 2 -> 1 test + 1 train; n >= 3 -> max(1, round(n * f_test)) test,
    max(1, round(n * f_val)) val, the rest train. So every source, content and actor appears
    in test, and in val where it has at least 3 clips. Independent of clip order. (An empty
    actor leaves the stratum, and so the split, as it was before actors were used.)
    """
    fr = fractions or SPLIT_FRACTIONS
    out = np.full(len(names), "train", dtype="<U7")
    given = [""] * len(names) if fixed is None else list(fixed)
    if len(given) != len(names):
        raise ValueError(f"fixed has {len(given)} entries for {len(names)} clips")
    held = np.array([bool(g) for g in given], dtype=bool)
    for i, g in enumerate(given):
        if g:
            out[i] = g
    who = [""] * len(names) if actors is None else list(actors)
    strata: dict[tuple[str, str, str], list[int]] = defaultdict(list)
    for i, key in enumerate(zip(sources, contents, who, strict=True)):
        if not held[i]:
            strata[key].append(i)
    for (source, content, actor), idx in strata.items():
        idx = sorted(idx, key=lambda i: names[i])
        stratum = f"{source}\0{content}" + (f"\0{actor}" if actor else "")
        crc = zlib.crc32(stratum.encode())
        rng = np.random.default_rng([seed & 0xFFFFFFFF, crc])
        order = [idx[i] for i in rng.permutation(len(idx))]
        n = len(order)
        if n <= 2:
            n_test, n_val = 1, 0
        else:
            n_test = max(1, round(n * fr["test"]))
            n_val = max(1, round(n * fr["val"]))
        for i in order[:n_test]:
            out[i] = "test"
        for i in order[n_test : n_test + n_val]:
            out[i] = "val"
    return out
