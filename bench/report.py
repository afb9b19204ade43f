"""The markdown report of a benchmark run: every table is generated from the run's
results (``results.json``), nothing is copied from elsewhere."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from bench.accuracy import STRESS_METHODS
from bench.edits import COMPOSED5, FIVE, METHOD_LABEL, METHODS, short
from bench.goals import goals, heldout_goals
from bench.heldout import COMPLETION, Family, HeldoutResults
from bench.heldout import METHODS as HELD_METHODS
from bench.markdown import fmt, table
from core.io import write_atomic

Json = dict[str, Any]


def write_json(results: Json, path: Path) -> None:
    write_atomic(path, (json.dumps(results, indent=1, default=float) + "\n").encode())


def edit_tables(block: Json, bench: str) -> list[str]:
    names = list(block)
    out = []
    for metric, title in (
        ("mpjpe", "MPJPE to the real pose, all joints (cm, mean)"),
        ("chain", "Chain MPJPE: untargeted joints between each target and the pelvis (cm)"),
        ("untargeted", "MPJPE of the untargeted joints (cm)"),
        ("reach_mean", "Reach error (cm, mean over targets)"),
    ):
        rows = [[short(n), *[fmt(block[n][m][metric]) for m in METHODS]] for n in names]
        out += [
            f"**{bench} — {title}**",
            "",
            table(["set", *[METHOD_LABEL[m] for m in METHODS]], rows),
            "",
        ]
    detail_rows = []
    for n in names:
        for m in METHODS:
            s = block[n][m]
            detail_rows.append(
                [
                    short(n),
                    METHOD_LABEL[m],
                    s["n"],
                    fmt(s["reach_mean"]),
                    fmt(s["reach_median"]),
                    fmt(s["reach_p95"]),
                    fmt(s["reach_within_1cm"], 1),
                    f"{fmt(s['reachable_pct'], 1)} / {fmt(s['reachable_within_1mm'], 1)}",
                    fmt(s["mpjpe"]),
                    fmt(s["untargeted"]),
                    fmt(s["chain"]),
                    fmt(s["drift"]),
                    fmt(s["bone_max"], 6),
                    fmt(s["floor_mean"], 3),
                    fmt(s["floor_over_1cm"], 1),
                    fmt(s["seconds"], 2),
                ]
            )
    out += [
        f"<details><summary>{bench}: every metric</summary>",
        "",
        table(
            [
                "set",
                "method",
                "n",
                "reach mean",
                "reach median",
                "reach p95",
                "% ≤ 1 cm",
                "% reachable / of those % ≤ 1 mm",
                "MPJPE",
                "MPJPE untargeted",
                "chain MPJPE",
                "drift from start",
                "max bone err",
                "floor pen. mean (cm)",
                "% floor pen. > 1 cm",
                "solve s (batch)",
            ],
            detail_rows,
        ),
        "",
        "</details>",
        "",
    ]
    return out


def render_report(results: Json, plots: dict[str, str], title: str) -> str:
    """The markdown report: every table is generated from ``results``."""
    md: list[str] = [f"# {title}", ""]
    models, data = results.get("models", {}), results.get("dataset", {})
    mach = results.get("machine_start", {})
    cfg = results.get("config", {})
    md += [
        f"Generated {results.get('generated', '')} by `{results.get('command', '')}`. "
        "Every number below was measured in this one run (nothing is copied from elsewhere).",
        "",
        f"- Models: `{models.get('dir')}` (manifest `{models.get('version')}`; service default "
        f"composition `{models.get('composition')}`, "
        + (
            "delta answers: a composed sequence runs once, the targets pasted before each "
            "later solver)."
            if models.get("delta")
            else f"{models.get('composition_projections')} projection(s), "
            f"{models.get('composition_passes')} pass(es))."
        ),
        f"- Data: TEST split of `{data.get('path')}`: {fmt(data.get('test_frames'))} frames in "
        f"{fmt(data.get('test_clips'))} clips never seen in training.",
        f"- Sample sizes: {cfg.get('edits')} B1 edits (the same pose pairs for every set), "
        f"{cfg.get('random_edits')} B3 edits per subset size, {cfg.get('completions')} B2 "
        f"poses per level, {cfg.get('paths')} B4 paths × {cfg.get('path_frames')} frames, "
        f"{cfg.get('stress')} B5 items per case; seed {cfg.get('seed')}.",
        f"- Machine: {mach.get('cpus')} CPUs, load average at start {mach.get('loadavg')} "
        f"(end {results.get('machine_end', {}).get('loadavg')}); Python "
        f"{mach.get('python')}, numpy {mach.get('numpy')}, onnxruntime "
        f"{mach.get('onnxruntime')}.",
        f"- Wall time (s): {results.get('seconds', {})}.",
        "",
        "## Goals",
        "",
        table(["goal", "target", "measured", "status"], goals(results)),
        "",
        "## Accuracy (TEST split)",
        "",
        "Methods: *identity* returns the start pose; *FABRIK* is the service's "
        "`method=fabrik` (full-body FABRIK from the start pose, no learned prior); "
        "*neural raw* is `preserve_bone_lengths=false`; *neural + bone pass* is the default "
        "(`reach=soft`); *neural + exact reach* is `reach=exact` (FABRIK polish, 1 mm "
        "tolerance). All distances in cm. Bone errors are relative to the start pose's bone "
        "lengths. *Drift* is the mean distance of the untargeted joints from the start pose; "
        "*floor pen.* is how far the lowest ankle/foot joint is below y = 0.",
        "",
    ]
    if "B1" in results:
        md += [
            "### B1 — edits (start and target pose of one clip, 0.2–1 s apart)",
            "",
            "Single-target edits are ambiguous (the rest of the body also moved between the "
            "two frames), so the chain MPJPE is the fairer view there.",
            "",
            *edit_tables(results["B1"], "B1"),
        ]
        for key, caption in (
            ("reach", "Reach error by method and target set"),
            ("mpjpe", "MPJPE distributions"),
            ("samples", "Sample solved poses"),
        ):
            if key in plots:
                md += [f"![{caption}]({plots[key]})", ""]
    if "B3" in results:
        md += [
            "### B3 — random subsets of 1–6 solver joints (composition beyond trained sets)",
            "",
            *edit_tables(results["B3"], "B3"),
        ]
    if results.get("B2"):
        rows = []
        for name, lvl in results["B2"].items():
            for m in ("rest_fabrik", "neural"):
                s = lvl[m]
                rows.append(
                    [
                        name,
                        "rest pose + FABRIK" if m == "rest_fabrik" else "completion",
                        s["n"],
                        fmt(s["mpjpe"]),
                        fmt(s["untargeted"]),
                        f"{fmt(s['reach_mean'])} / {fmt(s['reach_max'])}",
                        fmt(s["bone_vs_real_mean"], 4),
                        fmt(s["floor_mean"], 3),
                        fmt(lvl["ms_per_call"]) if m == "neural" else "–",
                    ]
                )
        md += [
            "### B2 — completion from key points only",
            "",
            "Key points are the real pose's joints of each completion level (from the "
            "manifest); no bone lengths are given, so the service uses the completion "
            "network's own estimate of the body's proportions. The "
            "baseline FABRIKs the reference rest pose (moved onto the pelvis) onto the "
            "key points.",
            "",
            table(
                [
                    "level",
                    "method",
                    "n",
                    "MPJPE",
                    "MPJPE non-key joints",
                    "key-point error mean / max",
                    "bone length vs real (mean rel.)",
                    "floor pen. mean",
                    "ms per call",
                ],
                rows,
            ),
            "",
        ]
    if results.get("B4"):
        b4 = results["B4"]
        rows = []
        for name in (k for k in b4 if isinstance(b4[k], dict)):
            for m, s in b4[name].items():
                rows.append(
                    [
                        short(name),
                        METHOD_LABEL[m],
                        fmt(s["jitter"]),
                        fmt(s["jitter_untargeted"]),
                        fmt(s["reach_mean"], 3),
                        fmt(s["mpjpe"]),
                        f"{fmt(s['untargeted_first'])} → {fmt(s['untargeted_last'])}",
                        fmt(s["bone_max"], 6),
                    ]
                )
        md += [
            "### B4 — drag paths",
            "",
            f"{b4['paths']} test clips, {b4['frames']} consecutive frames each (30 fps); "
            "targets follow the clip frame by frame and every solve starts from the previous "
            "result. Jitter = mean joint acceleration |p[t+1] − 2p[t] + p[t−1]| × fps² "
            f"(m/s²); the real clips have {fmt(b4['real_jitter'])} m/s². Drift = error of the "
            "untargeted joints to the real frame, first vs last 10 steps. Five targets: "
            "also with the turn search off (`options.turn_search: false`), as a client "
            "dragging may choose (docs/generalisation-serving.md item 22).",
            "",
            table(
                [
                    "targets",
                    "method",
                    "jitter (m/s²)",
                    "jitter untargeted",
                    "reach mean (cm)",
                    "MPJPE (cm)",
                    "untargeted error first → last (cm)",
                    "max bone err",
                ],
                rows,
            ),
            "",
        ]
        if "paths" in plots:
            md += [f"![B4 drift along drag paths]({plots['paths']})", ""]
    if results.get("B5"):
        b5 = results["B5"]
        rows = []
        for case, block in b5.items():
            for m in STRESS_METHODS:
                s = block[m]
                rows.append(
                    [
                        case,
                        METHOD_LABEL[m],
                        fmt(s["finite"], 1),
                        fmt(s["reach_mean"]),
                        fmt(s["mpjpe"]),
                        fmt(s.get("max_dev_mm"), 4),
                        fmt(s.get("bone_max_world", s["bone_max"]), 6),
                    ]
                )
        notes = [
            f"- *{case}*: {block['transform']}"
            for case, block in b5.items()
            if "transform" in block
        ]
        if "beyond_arm_cm" in b5.get("unreachable (2x arm length)", {}):
            notes.append(
                "- unreachable targets lie on average "
                f"{fmt(b5['unreachable (2x arm length)']['beyond_arm_cm'])} cm beyond the "
                "straight arm from the shoulder, so that is roughly the best possible error "
                "without moving the trunk."
            )
        md += [
            "### B5 — stress",
            "",
            f"Base problems: the first {cfg.get('stress')} B1 five-end-effector edits. The "
            "scaled and moved cases are the same problems, so their results are mapped back "
            "to the canonical frame and compared with the canonical run (*max deviation*); "
            "their MPJPE/reach are in canonical-size centimetres.",
            "",
            *notes,
            "",
            table(
                [
                    "case",
                    "method",
                    "% finite",
                    "reach mean (cm)",
                    "MPJPE (cm)",
                    "max deviation from canonical (mm)",
                    "max bone err",
                ],
                rows,
            ),
            "",
        ]
    if results.get("determinism"):
        det = results["determinism"]
        rows = [
            [
                METHOD_LABEL[m],
                fmt(v["repeat_bitwise_equal"]),
                fmt(v["single_vs_batch_max_abs_m"], 3),
            ]
            for m, v in det.items()
            if isinstance(v, dict)
        ]
        md += [
            "### Determinism",
            "",
            f"{det['n']} B1 five-target edits solved twice as identical batches (bits "
            "compared), and the first ones also solved one by one.",
            "",
            table(["method", "repeat bit-identical", "one-by-one vs batch max |Δ| (m)"], rows),
            "",
        ]
    if results.get("ablation"):
        abl = results["ablation"]
        rows = []
        for p, row in abl.items():
            for key in (f"B1 {COMPOSED5}", "B3 2+ joints"):
                for m in ("neural_raw", "neural_bone"):
                    s = row[f"{key}|{m}"]
                    rows.append(
                        [
                            p,
                            key,
                            METHOD_LABEL[m],
                            s["n"],
                            fmt(s["reach_mean"]),
                            fmt(s["reach_p95"]),
                            fmt(s["mpjpe"]),
                            fmt(s["chain"]),
                        ]
                    )
        md += [
            "### Composition ablation",
            "",
            "How a target set no single solver covers is served. *sequential (paper)*: "
            "ẑ = S_t3(S_t2(S_t1(z))); *passes*: cycles through that sequence; *re-encode*: "
            "before each later solver, decode, paste the targets solved so far and "
            "re-encode; *projections*: rounds of paste-all-targets and re-encode at the end "
            "(docs/service.md; passes and projections only on models without "
            "`serving.delta`, so their rows are left out for delta models). B1's pairs "
            "with five targets no trained set covers whole (head, "
            "both elbows, both knees: five single-joint solvers) and B3's subsets of 2 or "
            "more joints.",
            "",
            table(
                [
                    "strategy",
                    "set",
                    "method",
                    "n",
                    "reach mean",
                    "reach p95",
                    "MPJPE",
                    "chain MPJPE",
                ],
                rows,
            ),
            "",
        ]
        if "ablation" in plots:
            md += [f"![Composition ablation]({plots['ablation']})", ""]
    md += heldout_sections(results, plots)
    md += _speed_sections(results, plots)
    mb = models.get("bytes")
    if mb:
        md += [
            "## Model size on disk",
            "",
            table(
                ["bundle", "bytes", "kB", "paper"],
                [
                    [
                        "2-target set (" + " + ".join(mb["two_target_files"]) + ")",
                        fmt(mb["two_target_set"]),
                        fmt(mb["two_target_set"] / 1000, 0),
                        "442 kB",
                    ],
                    [
                        "autoencoder + every solver",
                        fmt(mb["solvers_and_autoencoder"]),
                        fmt(mb["solvers_and_autoencoder"] / 1000, 0),
                        "826 kB (full body)",
                    ],
                    [
                        f"all {mb['files']} model files (incl. completion)",
                        fmt(mb["all_models"]),
                        fmt(mb["all_models"] / 1000, 0),
                        "–",
                    ],
                ],
            ),
            "",
        ]
    return "\n".join(md).rstrip() + "\n"


def _speed_sections(results: Json, plots: dict[str, str]) -> list[str]:
    speed, http = results.get("speed"), results.get("http")
    if not speed and not http:
        return ["## Speed", "", "Not measured in this run (run `make bench`).", ""]
    md: list[str] = ["## Speed", ""]
    if results.get("http_error"):
        md += [f"**The HTTP part failed:** `{results['http_error']}`", ""]
    if speed:
        rows = [
            [
                r["targets"],
                short(r["set"]),
                METHOD_LABEL[r["method"]],
                r["n"],
                fmt(r["p50_ms"], 3),
                fmt(r["p99_ms"], 3),
                fmt(r["mean_ms"], 3),
            ]
            for r in speed["latency"]
        ]
        md += [
            "### In-process latency (one thread)",
            "",
            "`Engine(threads=1).solve([problem])` per call on B1 edits (a different edit "
            "each call), the neural and FABRIK runs interleaved in the same loop.",
            "",
            table(["targets", "set", "method", "calls", "p50 (ms)", "p99 (ms)", "mean (ms)"], rows),
            "",
            "FABRIK p50 / neural + bone pass p50: "
            + ", ".join(f"{k} targets **{v:.1f}×**" for k, v in speed["ratio"].items()),
            "",
        ]
        if "latency" in plots:
            md += [f"![Latency neural vs FABRIK]({plots['latency']})", ""]
        rows = [
            [
                r["batch"],
                METHOD_LABEL[r["method"]],
                r["items"],
                fmt(r["seconds"], 3),
                fmt(r["poses_per_s"], 0),
            ]
            for r in speed["throughput"]
        ]
        md += [
            "### In-process batch throughput (one thread)",
            "",
            f"One `Engine.solve` call per batch ({speed.get('throughput_set', '')}).",
            "",
            table(["batch size", "method", "poses", "seconds", "poses/s"], rows),
            "",
        ]
        if "throughput" in plots:
            md += [f"![Throughput vs batch size]({plots['throughput']})", ""]
    if http:
        rows = [
            [
                r["concurrency"],
                r["requests"],
                r["errors"],
                fmt(r["p50_ms"]),
                fmt(r["p99_ms"]),
                fmt(r["rps"], 0),
                fmt(r["seconds"], 1),
            ]
            for r in http["solve"]
        ]
        b = http.get("batch") or {}
        rss = http.get("rss_kb", {})
        one = next((r for r in http["solve"] if r["concurrency"] == 1), None)
        paced = http.get("solve_paced")
        md += [
            "### HTTP (uvicorn on loopback)",
            "",
            f"`{http.get('server')}` as a subprocess on 127.0.0.1, one worker "
            "(POSE_ORT_THREADS=1). Load generator: a raw asyncio HTTP/1.1 client in the "
            "benchmark process (bench/http_load.py), closed loop, one kept-alive "
            "connection per unit of concurrency, bounded in "
            f"requests and time ({http.get('limits')}); requests pre-built, answers read "
            "in full (status checked, bodies not parsed). "
            "The client shares the machine's "
            f"{results.get('machine_start', {}).get('cpus')} CPUs with the server.",
            "",
            f"/v1/solve ({http.get('solve_set')}):",
            "",
            table(
                [
                    "concurrency",
                    "requests",
                    "errors",
                    "p50 (ms)",
                    "p99 (ms)",
                    "requests/s",
                    "seconds",
                ],
                rows,
            ),
            "",
        ]
        if one and paced:
            md += [
                f"At concurrency 1 the server's own time (`X-Total-Time`) p50 was "
                f"{fmt(one['server_p50_ms'], 3)} ms, the engine's (`X-Compute-Time`) "
                f"{fmt(one['compute_p50_ms'], 3)} ms. The same requests sent at a drag's pace, "
                f"one every {paced['gap_ms']:.1f} ms as an editor sends them ("
                f"{paced['requests']} requests): p50 **{fmt(paced['p50_ms'], 3)} ms** (p99 "
                f"{fmt(paced['p99_ms'], 3)}), server {fmt(paced['server_p50_ms'], 3)} ms, engine "
                f"{fmt(paced['compute_p50_ms'], 3)} ms: between requests the server idles "
                "and its caches go cold (docs/speed.md).",
                "",
            ]
        if b:
            md += [
                f"/v1/solve/batch: {b['batches']} batches of {b['batch_size']} items at "
                f"concurrency {b['concurrency']}: **{b['poses_per_s']:,.0f} poses/s** "
                f"(p50 {b['p50_ms']:.0f} ms per batch, {b['errors']} errors).",
                "",
            ]
        if rss:
            md += [
                "Service RSS (VmRSS from /proc): "
                + ", ".join(f"{k.replace('_', ' ')} {v / 1024:.1f} MiB" for k, v in rss.items())
                + ".",
                "",
            ]
    return md


# --------------------------------------------------------------------------------------
# Held-out bodies (bench.heldout)
# --------------------------------------------------------------------------------------
def _mp(block: Any, method: str) -> str:
    return fmt(block[method].mpjpe) if block and method in block else "–"


def _world_cells(name: str, studio: Family | None, block: Any) -> list[str]:
    """One set's world-edit cells: start, FABRIK, soft (completion's own answer for the
    completion set) and exact on the TEST split (``studio``), the same on the held-out
    ``block``, and the held-out soft reach."""
    soft = "completion" if name == COMPLETION else "neural_bone"
    methods = ("identity", "fabrik", soft, "neural_exact")
    st = studio.sets.get(name, {}) if studio else {}
    return [
        *(_mp(st, m) for m in methods),
        *(_mp(block, m) for m in methods),
        fmt(block[soft].reach_mean),
    ]


def heldout_sections(results: Json, plots: dict[str, str]) -> list[str]:
    """The held-out goals, the side-by-side table, the plot and per-family details."""
    if results.get("heldout_skipped"):
        return [
            "## Held-out bodies (world-space edits)",
            "",
            f"Not measured: {results['heldout_skipped']}.",
            "",
        ]
    if not results.get("heldout"):
        return []
    h = HeldoutResults.from_json(results["heldout"])
    cfg = h.config
    pooled, studio = h.pooled(), h.studio()
    b1 = results.get("B1", {})
    md: list[str] = [
        "## Held-out bodies (world-space edits)",
        "",
        "Bodies no model was trained on (the dataset's `holdout` split), one family per "
        "source and all pooled; and a stress set of TEST poses rebuilt as other bodies "
        "(`core.bodies`). Each edit: frames i, j of one clip 0.2–1 s apart; the target pose is "
        "frame j in WORLD space, the start is frame i moved onto frame j's pelvis (the body "
        "may have turned in between); targets are the target pose's joints. Methods: the "
        "start pose unchanged, FABRIK, neural + bone pass (soft) and neural + exact reach, "
        "through `Engine.solve` with B1's options; 6-point completion is `Engine.complete` "
        "on the target's six base key points (no bone lengths, as B2), beside FABRIK from "
        "the start onto them. MPJPE to the real target pose, cm. "
        f"{cfg.get('edits')} edits per set over the held-out sources together, "
        f"{cfg.get('stress')} per set per stress family; seed {cfg.get('seed')}.",
        "",
        "### Goals on held-out bodies (issue 11)",
        "",
        table(["goal", "target", "measured", "status"], heldout_goals(h)),
        "",
    ]
    if pooled is not None:
        rows = []
        for name, block in pooled.sets.items():
            b = b1.get(name, {})
            rows.append(
                [
                    short(name),
                    fmt(b.get("fabrik", {}).get("mpjpe")),
                    fmt(b.get("neural_bone", {}).get("mpjpe")),
                    *_world_cells(name, studio, block),
                ]
            )
        md += [
            "### Held-out bodies beside the in-studio test split",
            "",
            "MPJPE to the real target pose (cm). *B1*: the in-studio canonical edits above; "
            "*TEST world*: the same world-space edits on the TEST split "
            f"({studio.frames if studio else 0:,} frames); "
            f"*held-out*: {', '.join(pooled.sources)} ({pooled.clips} clips, "
            f"{pooled.frames:,} frames). Turn between start and target frame: held-out p50 "
            f"{pooled.turn_p50:.1f}°, p90 {pooled.turn_p90:.1f}°"
            + (f"; TEST p50 {studio.turn_p50:.1f}°, p90 {studio.turn_p90:.1f}°" if studio else "")
            + ". For 6-point completion the *soft* column is `Engine.complete`.",
            "",
            table(
                [
                    "set",
                    "B1 FABRIK",
                    "B1 soft",
                    "TEST world start",
                    "FABRIK",
                    "soft",
                    "exact",
                    "held-out start",
                    "FABRIK",
                    "soft",
                    "exact",
                    "held-out reach soft",
                ],
                rows,
            ),
            "",
        ]
        if "heldout" in plots:
            md += [f"![Held-out MPJPE by set and method]({plots['heldout']})", ""]
    md += _family_summary(h)
    if pooled is not None:
        md += [
            f"**MPJPE by turn between start and target ({pooled.name}; every edit set, "
            "items counted once per set)**",
            "",
            table(
                ["turn", "items", *(METHOD_LABEL[m] for m in HELD_METHODS)],
                [
                    [r.bucket, fmt(r.n), *(fmt(r.mpjpe.get(m)) for m in HELD_METHODS)]
                    for r in pooled.by_turn
                ],
            ),
            "",
        ]
    md += _family_details(h)
    return md + captured_section(results)


#: The columns of :func:`captured_section`'s table.
CAPTURED_HEAD = [
    "set", "TEST start", "FABRIK", "soft", "exact",
    "held-out start", "FABRIK", "soft", "exact", "held-out reach soft",
]  # fmt: skip


def captured_section(results: Json) -> list[str]:
    """The same edits with each start left where it was captured (``bench.heldout
    --captured``): the body's travel between the two frames is left in."""
    if not results.get("captured"):
        return []
    h = HeldoutResults.from_json(results["captured"])
    pooled, studio = h.pooled(), h.studio()
    if pooled is None:
        return []
    rows = [
        [short(name), *_world_cells(name, studio, block)]
        for name, block in pooled.sets.items()
        if name != COMPLETION
    ]
    return [
        "### The same edits, starts where they were captured",
        "",
        "As above, but each start stays where it was captured instead of on its target's "
        "pelvis, so the body's travel between the two frames (walking included) is left in "
        "(`python -m bench.heldout --captured`; docs/generalisation-serving-2.md items 32–34). "
        "MPJPE to the real target pose, cm.",
        "",
        table(CAPTURED_HEAD, rows),
        "",
    ]


def _family_summary(h: HeldoutResults) -> list[str]:
    rows = []
    for f in h.families:
        edit = {k: v for k, v in f.sets.items() if k != COMPLETION}
        mean = {m: sum(v[m].mpjpe for v in edit.values()) / len(edit) for m in HELD_METHODS}
        five = edit.get(FIVE)
        comp = f.sets.get(COMPLETION, {}).get("completion")
        rec = f.recon
        rows.append(
            [
                f.name,
                fmt(next(iter(edit.values()))["identity"].n) if edit else "–",
                f"{fmt(f.turn_p50, 1)} / {fmt(f.turn_p90, 1)}",
                *(fmt(mean[m]) for m in HELD_METHODS),
                f"{sum(v['neural_bone'].mpjpe < v['fabrik'].mpjpe for v in edit.values())}"
                f"/{len(edit)}",
                fmt(five["neural_bone"].mpjpe / five["fabrik"].mpjpe) if five else "–",
                fmt(sum(v["neural_bone"].reach_mean for v in edit.values()) / len(edit)),
                fmt(comp.mpjpe if comp else None),
                "–" if rec is None else f"{rec.mean:.2f} / {rec.wrists:.2f} ({rec.worst_joint})",
            ]
        )
    return [
        "### Families",
        "",
        "MPJPE mean over the edit sets (cm); *AE recon*: `Engine.reconstruct` of the "
        "family's poses, mean / wrists (worst joint)"
        + ("" if h.recon_available else " (this engine has no `reconstruct`: not measured)")
        + ".",
        "",
        *(f"- *{f.name}*: {f.note}" for f in h.families if f.note),
        "",
        table(
            [
                "family",
                "edits/set",
                "turn p50 / p90 (°)",
                *(METHOD_LABEL[m] for m in HELD_METHODS),
                "soft < FABRIK",
                "5 eff. soft / FABRIK",
                "reach soft",
                "6-point completion",
                "AE recon mean / wrists",
            ],
            rows,
        ),
        "",
    ]


def _family_details(h: HeldoutResults) -> list[str]:
    md: list[str] = []
    for f in h.families:
        rows = [
            [
                short(name),
                METHOD_LABEL[m],
                fmt(s.n),
                fmt(s.mpjpe),
                fmt(s.chain),
                fmt(s.reach_mean),
                fmt(s.reach_p95),
                fmt(s.bone_max, 6),
                fmt(s.ms_per_edit, 3),
            ]
            for name, block in f.sets.items()
            for m, s in block.items()
        ]
        md += [
            f"<details><summary>{f.name}: every set and method</summary>",
            "",
            table(
                [
                    "set",
                    "method",
                    "n",
                    "MPJPE",
                    "chain MPJPE",
                    "reach mean",
                    "reach p95",
                    "max bone err",
                    "ms / edit",
                ],
                rows,
            ),
            "",
            "</details>",
            "",
        ]
    return md
