"""A character's rig, its skeleton and joint map, made once for the requests that send the
same character again: an editor sends one file's hierarchy with every edit, and a tool its
character's joints. Both are kept read-only and bounded, and an answer from a kept rig is
the first answer byte for byte (``tests/service/test_rigs.py``; docs/speed.md).

- A BVH file's (:func:`bvh_rig`): in its hierarchy's ``BVH.memo``, which the files of that
  hierarchy share (``core.bvh.SHARED``): the skeleton once, and the maps of up to
  :data:`MAPS_PER_SKELETON` requests' ``joint_map``.
- A JSON character's (:func:`json_skeleton`, :func:`json_map`): the last
  :data:`SKELETONS` skeletons sent, keyed by a digest of their joints' names, parents and
  offsets, and the last ``SKELETONS * MAPS_PER_SKELETON`` joint maps made for them. Their
  errors are made again with the field of the request that sent them (a batch's item
  names its own).
"""

from __future__ import annotations

import hashlib
import json
import threading
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast

import numpy as np

from core.bvh import BVH
from core.bvh_write import skeleton_of
from core.characters import CharacterError, Skeleton, build_skeleton
from core.characters_maps import JointMap, resolve_map

Rig = tuple[Skeleton, JointMap]
#: the most joint maps kept for one skeleton
MAPS_PER_SKELETON = 4
#: JSON characters' skeletons kept (the last sent)
SKELETONS = 8


def bvh_rig(bvh: BVH, joint_map: Mapping[str, str] | None) -> Rig:
    """The file's skeleton and joint map (the same for each of its frames, and for every
    file of its hierarchy: kept in ``bvh.memo``); raises as ``skeleton_of`` and
    ``resolve_map`` do."""
    memo = bvh.memo
    key = f"rig {list((joint_map or {}).items())!r}"
    if (found := memo.get(key)) is not None:
        return cast(Rig, found)
    skel = cast(Skeleton | None, memo.get("skeleton")) or skeleton_of(bvh)
    jmap = resolve_map(skel, joint_map, offset_at=lambda _: "bvh")
    # (read-only before either is kept: two threads may each make one; both are the same)
    rig = _read_only_skeleton(skel), _read_only_map(jmap)
    with _LOCK:  # the count and the keeping at once: two threads each saw 3 and kept 5
        memo.setdefault("skeleton", skel)
        if key not in memo and sum(k.startswith("rig ") for k in memo) < MAPS_PER_SKELETON:
            memo[key] = rig
    return rig


Joints = tuple[Sequence[str], Sequence[str | None], Sequence[Sequence[float]]]
_SKELETONS: OrderedDict[bytes, tuple[Skeleton, list[int]]] = OrderedDict()
_MAPS: OrderedDict[tuple[bytes, str], JointMap] = OrderedDict()
_LOCK = threading.Lock()


def json_skeleton(joints: Joints, where: str) -> tuple[Skeleton, list[int], bytes]:
    """``build_skeleton`` of a JSON character's (names, parents, offsets), its errors
    naming ``where``; with the digest :func:`json_map` takes (empty where not kept)."""
    names, parents, offsets = joints
    try:
        digest = _digest(names, parents, offsets)
    except (TypeError, ValueError):  # (offsets not 3 numbers each: build_skeleton says so)
        skel, order = build_skeleton(list(names), list(parents), list(offsets), where=where)
        return skel, order, b""
    try:
        skel, order = _kept(_SKELETONS, digest, SKELETONS, lambda: _new_skeleton(joints))
    except CharacterError:  # made again, so that the error names the request's field
        skel, order = build_skeleton(list(names), list(parents), list(offsets), where=where)
    return skel, list(order), digest


def json_map(
    skel: Skeleton, digest: bytes, joint_map: Mapping[str, str] | None, where: str,
    offset_at: Callable[[int | None], str],
) -> JointMap:  # fmt: skip
    """``resolve_map`` of a skeleton :func:`json_skeleton` gave, its errors naming
    ``where`` and ``offset_at``'s fields."""
    if not digest:
        return resolve_map(skel, joint_map, where=where, offset_at=offset_at)
    key = (digest, json.dumps(list((joint_map or {}).items())))
    try:
        made = _kept(_MAPS, key, SKELETONS * MAPS_PER_SKELETON,
                     lambda: _read_only_map(resolve_map(skel, joint_map)))  # fmt: skip
        return cast(JointMap, made)
    except CharacterError:
        return resolve_map(skel, joint_map, where=where, offset_at=offset_at)


def _kept(store: OrderedDict[Any, Any], key: Any, size: int, make: Callable[[], Any]) -> Any:
    """``store[key]``, made by ``make`` where it is not kept; the last ``size`` kept."""
    with _LOCK:
        if key in store:
            store.move_to_end(key)
            return store[key]
    value = make()
    with _LOCK:
        store[key] = value
        while len(store) > size:
            store.popitem(last=False)
    return value


def _new_skeleton(joints: Joints) -> tuple[Skeleton, list[int]]:
    names, parents, offsets = joints
    skel, order = build_skeleton(list(names), list(parents), list(offsets))
    return _read_only_skeleton(skel), order


def _digest(
    names: Sequence[str], parents: Sequence[str | None], offsets: Sequence[Sequence[float]]
) -> bytes:
    """What keys a JSON character's skeleton: its joints' names, parents and offsets (each
    offset three numbers: else ValueError)."""
    floats = np.asarray(offsets, dtype=np.float64)
    if floats.shape != (len(names), 3):
        raise ValueError("offsets are not three numbers each")
    h = hashlib.blake2b(digest_size=16)
    h.update(json.dumps([list(names), list(parents)]).encode())
    h.update(floats.tobytes())
    return h.digest()


def _read_only_skeleton(skel: Skeleton) -> Skeleton:
    for a in (skel.offsets, skel.parent_array):
        a.setflags(write=False)
    return skel


def _read_only_map(jmap: JointMap) -> JointMap:
    for a in (jmap.joints, jmap.offsets, *(anchor.offset for anchor in jmap.anchors)):
        a.setflags(write=False)
    return jmap
