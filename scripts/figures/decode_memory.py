"""Peak RSS of a fresh ``pose-service`` under N bodies of one shape sent at once
(docs/limits.md, "A body wrong in many places": "Of every route's body of each shape at
six and at eight at once").

Each case is one route's body of one shape, 8.3 MB (unknown keys, long lists of numbers,
empty objects or lists, deep nesting, one long string, the item and columnar forms,
character and BVH bodies, and the heavy valid bodies the limits admit), sent N times at
once to a fresh server (``tests/service/server.py``'s ``serve``, this tree, the default
settings, 127.0.0.1:18750-18799); one Markdown row per case and N: the server's RSS
before, its peak (VmHWM, reset before the requests) and after, the answers' statuses,
the wall time and the slowest ``/v2/health/live`` answer meanwhile (a probe every 10 ms).
A summary follows the table. 32 shapes × 2 sizes: 5-10 min on a 2-core host.

    PYTHONPATH=. python scripts/figures/decode_memory.py               # every case, N = 6 and 8
    PYTHONPATH=. python scripts/figures/decode_memory.py --only bvh 8
"""

from __future__ import annotations

import argparse
import contextlib
import json
import random
import threading
import time
from collections.abc import Callable
from typing import Any

from loopback import Answer, at_once, example, host_load, reset_peak, server, statuses, vm_mib

from tests.service.server import heavy_batch, solve_item

SIZE = 8_300_000
FILL = "__FILL__"
Body = dict[str, Any]


def fill(prefix: str, unit: str, suffix: str) -> bytes:
    """``prefix`` + ``unit,unit,…`` + ``suffix``, SIZE bytes."""
    n = (SIZE - len(prefix) - len(suffix)) // (len(unit) + 1)
    return (prefix + ",".join([unit] * n) + suffix).encode()


def unknown_keys(body: Body) -> bytes:
    """``body`` with keys ``k0``, ``k1``, … added up to SIZE."""
    head = json.dumps(body)[:-1] + ","
    keys: list[str] = []
    size = len(head)
    while size < SIZE - 20:
        key = f'"k{len(keys)}":0'
        keys.append(key)
        size += len(key) + 1
    return (head + ",".join(keys) + "}").encode()


def around(body: Body, path: list[Any]) -> tuple[str, str]:
    """``body``'s JSON before and after the value at ``path``."""
    node = body
    for step in path[:-1]:
        node = node[step]
    node[path[-1]] = FILL
    pre, post = json.dumps(body).split(f'"{FILL}"')
    return pre, post


def in_place(body: Body, path: list[Any], unit: str) -> bytes:
    """``body`` with the value at ``path`` a list of ``unit`` filling SIZE."""
    pre, post = around(body, path)
    return fill(pre + "[", unit, "]" + post)


def deep(body: Body, path: list[Any], depth: int = 200) -> bytes:
    return in_place(body, path, "[" * depth + "0" + "]" * depth)


def long_string(body: Body, path: list[Any]) -> bytes:
    pre, post = around(body, path)
    return (pre + '"' + "a" * (SIZE - len(pre) - len(post) - 2) + '"' + post).encode()


def many_items(item: Body) -> bytes:
    return fill('{"items":[', json.dumps(item, separators=(",", ":")), "]}")


def pose_row() -> list[float]:
    return [v for joint in example("solve")["pose"].values() for v in joint]


COLUMNAR_HEAD = '{"targets":{"joints":["head"],"positions":[[0,1,0]]},"poses":['


def big_bvh() -> str:
    """The example's BVH with its last frame repeated up to SIZE."""
    text = example("bvh_solve")["bvh"]
    head, motion = text.split("MOTION")
    frame = motion.strip().splitlines()[-1]
    n = (SIZE - len(text)) // (len(frame) + 1)
    return f"{head}MOTION\nFrames: {n}\nFrame Time: 0.033333\n" + "\n".join([frame] * n) + "\n"


def bvh_solve_big() -> bytes:
    return json.dumps({**example("bvh_solve"), "bvh": big_bvh(), "frame": 0}).encode()


def columnar_1024(seed: int = 0) -> bytes:
    """1,024 valid columnar edits: the example's pose jittered, head and left wrist moved."""
    rng = random.Random(seed)
    row = pose_row()
    rows = [[round(v + rng.uniform(-0.01, 0.01), 5) for v in row] for _ in range(1024)]
    positions = [[r[12], r[13] + 0.1, r[14], r[24] + 0.1, r[25], r[26]] for r in rows]
    targets = {"joints": ["head", "left_wrist"], "positions": positions}
    return json.dumps({"poses": rows, "targets": targets}).encode()


def ex(name: str) -> Body:
    return example(name)


SOLVE, BATCH, CHAR = "/v1/solve", "/v1/solve/batch", "/v1/character/solve"
CASES: dict[str, tuple[str, Callable[[], bytes]]] = {
    "solve/unknown_keys": (SOLVE, lambda: unknown_keys(ex("solve"))),
    "solve/numbers_in_position": (
        SOLVE,
        lambda: in_place(ex("solve"), ["targets", 0, "position"], "0.5"),
    ),
    "solve/floats_distinct": (
        SOLVE,
        lambda: in_place(ex("solve"), ["targets", 0, "position"], "0.123"),
    ),
    "solve/tiny_objects_targets": (SOLVE, lambda: in_place(ex("solve"), ["targets"], "{}")),
    "solve/empty_lists_pins": (SOLVE, lambda: in_place(ex("solve"), ["pins"], "[]")),
    "solve/deep_nesting": (SOLVE, lambda: deep(ex("solve"), ["targets"])),
    "solve/long_string": (SOLVE, lambda: long_string(ex("solve"), ["targets", 0, "joint"])),
    "solve/many_short_strings": (SOLVE, lambda: in_place(ex("solve"), ["pins"], '"ab"')),
    "solve_char/tiny_objects_joints": (
        SOLVE,
        lambda: in_place(ex("solve_character"), ["character", "joints"], "{}"),
    ),
    "solve_char/unknown_keys": (SOLVE, lambda: unknown_keys(ex("solve_character"))),
    "batch/unknown_keys": (BATCH, lambda: unknown_keys({"items": [ex("solve")]})),
    "batch/tiny_object_items": (BATCH, lambda: in_place({"items": []}, ["items"], "{}")),
    "batch/too_many_valid_items": (BATCH, lambda: many_items(ex("solve"))),
    "batch/numbers_in_position": (
        BATCH,
        lambda: in_place({"items": [ex("solve")]}, ["items", 0, "targets", 0, "position"], "0.5"),
    ),
    "batch/deep_nesting": (BATCH, lambda: deep({"items": []}, ["items"])),
    "columnar/too_many_rows": (BATCH, lambda: fill(COLUMNAR_HEAD, json.dumps(pose_row()), "]}")),
    "columnar/short_rows": (BATCH, lambda: fill(COLUMNAR_HEAD, json.dumps(pose_row()[:1]), "]}")),
    "columnar/empty_rows": (BATCH, lambda: fill(COLUMNAR_HEAD, "[]", "]}")),
    "columnar/numbers_one_row": (BATCH, lambda: fill(COLUMNAR_HEAD + "[", "0.5", "]]}")),
    "columnar/tiny_objects": (BATCH, lambda: fill(COLUMNAR_HEAD, "{}", "]}")),
    "complete/tiny_objects": (
        "/v1/complete",
        lambda: in_place(ex("complete"), ["keypoints"], "{}"),
    ),
    "complete/unknown_keys": ("/v1/complete", lambda: unknown_keys(ex("complete"))),
    "character/tiny_objects_joints": (
        CHAR,
        lambda: in_place(ex("character_solve"), ["skeleton", "joints"], "{}"),
    ),
    "character/numbers": (CHAR, lambda: in_place(ex("character_solve"), ["root_position"], "0.5")),
    "character/rotations_keys": (CHAR, lambda: unknown_keys(ex("character_solve"))),
    "bvh_solve/tiny_objects_targets": (
        "/v1/bvh/solve",
        lambda: in_place(ex("bvh_solve"), ["targets"], "{}"),
    ),
    "bvh_solve/big_valid_bvh": ("/v1/bvh/solve", bvh_solve_big),
    "bvh_inspect/unknown_keys": (
        "/v1/bvh/inspect",
        lambda: unknown_keys({"bvh": ex("bvh_solve")["bvh"]}),
    ),
    "bvh_inspect/big_valid_bvh": (
        "/v1/bvh/inspect",
        lambda: json.dumps({"bvh": big_bvh()}).encode(),
    ),
    "legit/items_1024_exact": (BATCH, lambda: heavy_batch(1024)),
    "legit/items_1024_soft": (
        BATCH,
        lambda: json.dumps({"items": [solve_item(i, exact=False) for i in range(1024)]}).encode(),
    ),
    "legit/columnar_1024": (BATCH, columnar_1024),
}


def run(name: str, n: int) -> tuple[float, list[Answer]]:
    """One case at N at once on a fresh server: its row printed, its peak and answers."""
    path, build = CASES[name]
    body = build()
    with server() as s:
        pid = s.proc.pid
        time.sleep(0.3)
        reset_peak(pid)
        base = vm_mib(pid, "VmRSS")
        probes: list[float] = []
        done = threading.Event()

        def probe() -> None:
            while not done.is_set():
                t = time.perf_counter()
                with contextlib.suppress(OSError):
                    s.request("GET", "/v2/health/live", timeout=30)
                probes.append(time.perf_counter() - t)
                time.sleep(0.01)

        prober = threading.Thread(target=probe)
        prober.start()
        t0 = time.perf_counter()
        answers = at_once(s, path, [body] * n)
        wall = time.perf_counter() - t0
        done.set()
        prober.join()
        peak, after = vm_mib(pid, "VmHWM"), vm_mib(pid, "VmRSS")
    print(
        f"| {name} | {path} | {len(body) / 1e6:.1f} MB | {n} | {base:.0f} | {peak:.0f} | "
        f"{after:.0f} | {statuses(answers)} | {wall:.2f} | {max(probes) * 1000:.0f} |",
        flush=True,
    )
    return peak, answers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("n", type=int, nargs="*", default=[6, 8], help="bodies at once")
    parser.add_argument("--only", action="append", default=[], help="cases naming this")
    args = parser.parse_args()
    print(
        "| case | route | body | N | base MiB | peak MiB | after MiB | statuses | wall s "
        "| max live ms |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    peaks: dict[tuple[str, int], float] = {}
    admitted: list[float] = []
    timeouts = 0
    for name in CASES:
        if args.only and not any(o in name for o in args.only):
            continue
        for n in args.n:
            peak, answers = run(name, n)
            peaks[name, n] = peak
            if name.split("/")[0] != "legit" and any(a.status != 413 for a in answers):
                admitted.append(peak)  # an 8.3 MB body the budget let in
            timeouts += sum(a.status == 408 for a in answers)
    (top_name, top_n), top = max(peaks.items(), key=lambda kv: kv[1])
    print(f"\n{len(peaks)} cases; highest peak {top:.0f} MiB ({top_name}, N={top_n}); ", end="")
    if admitted:
        low, high = min(admitted), max(admitted)
        print(
            f"8.3 MB bodies the budget admits (not 413) peak at {low:.0f}–{high:.0f} MiB; ",
            end="",
        )
    print(f"{timeouts} answers 408", host_load())


if __name__ == "__main__":
    main()
