"""The training ablation's table: one row per variant, scored on held-out bodies.

``scripts/ablation.sh`` trains every variant of ``trainer/configs/ablation/`` at a small
budget and scores it with ``python -m bench.heldout`` into ``reports/ablation/<name>.json``;
``python -m bench.ablation`` reads those files and writes ``reports/ablation.md``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer

from core.io import write_atomic

#: What each variant changes against ``full`` (the recipe of ``previous`` at the ablation
#: budget), or, for full-budget rows, what it is.
VARIANTS: dict[str, str] = {
    "shipped-before": "the models shipped before issue 11 (full budget, old recipe)",
    "no_augment": "no random bodies, no mirror, no size normalisation",
    "no_bodies": "mirror kept; recorded bodies only, no size normalisation",
    "world_pairs": "solver pairs in the start's frame (goal turned and moved), AE sees turns",
    "no_delta": "the paper's answer D(S(z, t))",
    "no_anchor": "delta answer start + D(S(z, t)) - D(z), not anchored",
    "full": "`previous`'s recipe at the small budget: canonical pairs, random bodies, mirror, "
    "size normalisation, anchored delta, stay term",
    "long_solvers": "full budget, world-frame pairs, 5 solver epochs (8k steps), no stay term",
    "shipped-world-pairs": "full budget, world-frame pairs, 1 solver epoch, stay term",
    "previous": "the models shipped before this round: `full`'s recipe at its full budget "
    "(200x200 -> 64 autoencoder, one pass)",
    "previous_2passes": "`previous` served with two passes (`--serving passes=2`)",
    "rigid": "`previous` + solvers trained on the bone-passed answer "
    "(trainer/configs/ablation/rigid.toml), one pass",
    "ae512": "`rigid` with a 512x512 -> 128 autoencoder (trainer/configs/ablation/ae512.toml), "
    "one pass",
    "ae512_2passes": "`ae512` served with two passes",
    "ae512_3passes": "`ae512` served with three passes",
    "c12": "the models shipped before this round (mx1-66cae476c74c, run exp_c12, "
    "ablation/base_c12.toml): `rigid` served with two passes",
    "c12_3passes": "`c12` served with three passes",
    "stay0": "`c12` with no stay term (solver.stay_weight 0 against 0.1; only the solvers "
    "retrained, trainer/configs/ablation/stay0.toml)",
    "stay03e2": "`c12` with stay_weight 0.3 and two solver epochs (stay03e2.toml)",
    "stay1": "`c12` with stay_weight 1.0 (stay1.toml)",
    "solver256": "`c12` with wider solvers, 3 x 256 hidden against 3 x 126 "
    "(solver256.toml): ~2x the time per network run",
    "completion512": "`c12` with wider completion networks, 512-512-512-256 against "
    "300-400-300-200 (completion512.toml; autoencoder and solvers the shipped ones)",
    "eff5": "`c12` with a 5-end-effector solver added to the shared bank, one epoch (eff5.toml)",
    "eff5only_e1": "a bank of the 5-end-effector solver alone, 1 epoch (eff5only_e1.toml; "
    "the other sets have no solver there: read its 5 end effectors row only)",
    "eff5only_e3": "the same, 3 epochs",
    "eff5only_e8": "the same, 8 epochs",
    "eff5only_e16": "the same, 16 epochs",
    "lift1": "`c12` with every solver pair's start lifted onto the goal's pelvis height "
    "(augment.lift_start 1.0, lift1.toml)",
    "lift075": "`c12` with three quarters of the starts lifted (lift075.toml)",
    "lift05": "`c12` with half of the starts lifted (lift05.toml)",
    "pairs_long": "`c13` with the two pair solvers (wrists, ankles) also trained apart "
    "for 8 epochs (pairs_long.toml; the single-joint bank then holds 12 sets)",
    "c13": "the models shipped before this round (run exp_c13, ablation/base_c13.toml): "
    "`lift05` plus the 5-end-effector solver trained apart for 8 epochs (solver.long_sets)",
    "solver_distance": "`c13` with the solvers' joint terms as mean per-joint distances "
    "instead of MSEs (solver.joint_loss, solver_distance.toml; both banks retrained)",
    "views": "`c13` served with completion over 4 turns x mirror (serving.completion_yaws, "
    "completion_mirror; views.toml, no training)",
    "completion_mpjpe": "`c13` with completion trained on the mean per-joint distance "
    "(completion.loss, completion_mpjpe.toml; 12 epochs, one view)",
    "completion_mpjpe_views": "`completion_mpjpe` served over 4 turns x mirror",
    "completion_mpjpe_e20": "`completion_mpjpe` with 20 completion epochs, one view",
    "c14": "run exp_c14 (ablation/base_c14.toml), shipped before `other003`: "
    "`c13`'s autoencoder and solvers, completion_mpjpe_e20's completion, served over 4 turns "
    "x mirror",
    "ae40": "`c14` with the autoencoder trained 40 epochs instead of 20 (ae40.toml); "
    "both solver banks retrained on it, the shipped completion reused",
    "stay_local": "`c14` with the stay term on each joint's offset from its parent "
    "(solver.stay_frame local, stay_local.toml; both solver banks retrained)",
    "stay_local03": "`stay_local` with the stay term weighted 0.3 (stay_local03.toml)",
    "other003": "`c14` with the goal's other joints weighted 0.03 instead of 0.01 "
    "(solver.other_weight, other003.toml; both solver banks retrained): shipped since, run "
    "exp_c15",
    "other01": "`c14` with solver.other_weight 0.1 (other01.toml)",
    "other01_local": "`other01` with the stay term in the local frame (other01_local.toml)",
    "other03": "`c14` with solver.other_weight 0.3 (other03.toml)",
    "carry025": "`other003`'s networks (exp_c15) served with the branch below each target "
    "turned 0.25 of the way with the target's bone (serving.carry; `python -m bench.heldout "
    "--serving carry=0.25`)",
    "carry05": "`other003` served with serving.carry 0.5: shipped since (mx1-405fce5f4421)",
    "carry075": "`other003` served with serving.carry 0.75",
    "carry1": "`other003` served with serving.carry 1 (the branch carried rigidly, as FABRIK)",
    "carry_loss": "the shipped recipe with the solvers trained on the answer with the carry "
    "(solver.carry_loss, carry_loss.toml; both solver banks retrained)",
    "turn12_min3": "`carry05` served with the turn search (serving.turn_yaws 12, margin 1 cm) "
    "for edits with 3 or more targets",
    "turn12_min4": "the same for edits with 4 or more targets",
    "turn12_min5": "the same for edits with 5 or more targets (mx1-00ce505b05cf)",
    "turn12_plaus1": "`turn12_min5` scoring candidates by reach + 1 x the answer's distance to "
    "its autoencoder round trip (serving.turn_plausibility): shipped since (mx1-c9e21949f9e0)",
    "ae40_o3": "the shipped recipe (other_weight 0.03, carry 0.5) with the autoencoder trained "
    "40 epochs (ae40_o3.toml; both solver banks retrained on it, completion reused)",
    "ae_cos1e3": "the shipped recipe with the autoencoder at lr 1e-3 decayed along a cosine "
    "(autoencoder.lr_schedule, ae_cos1e3.toml; same 20 epochs; both solver banks retrained, "
    "completion as shipped)",
    "ae_cos3e3": "the same at lr 3e-3 (ae_cos3e3.toml); both scored with the autoencoder "
    "critic of `turn12_plaus1`",
    "ae_cos1e3_critic": "`ae_cos1e3` served with the completion critic (as `critic_completion05`)",
    "ae_cos3e3_critic": "`ae_cos3e3` served with the completion critic (as `critic_completion05`)",
    "critic_completion1": "`turn12_plaus1` with the candidates scored by reach + 1 x the "
    "answer's distance to the body completion level 1 builds from its base key points "
    "(serving.turn_critic completion)",
    "critic_completion05": "the same at 0.5 (serving.turn_plausibility): shipped since "
    "(mx1-78eb3e10e6ac)",
    "critic_3passes": "`critic_completion05` served with three passes for every edit "
    "(`--serving passes=3`)",
    "retry05cm": "`critic_completion05` with one more pass for soft answers still more than "
    "0.5 cm from a target (serving.retry_reach 0.005)",
    "retry1cm": "the same at 1 cm",
    "retry2cm": "the same at 2 cm: shipped since (mx1-dc18b1ee350b)",
    "ae_cos3e3_retry": "`ae_cos3e3_critic` with the retry at 2 cm (as shipped, on item 23's "
    "autoencoder)",
    "ae_cos3e3_long3": "`ae_cos3e3_retry` with its 5-end-effector solver trained 3 epochs "
    "instead of 8 (ae_cos3e3_long3.toml; served as shipped)",
    "ae_cos3e3_long16": "the same, 16 epochs (ae_cos3e3_long16.toml)",
    "elbows_long_e3": "the shipped recipe with the two elbow solvers trained apart (the long "
    "bank) for 3 epochs instead of one epoch in the shared bank; no 5-end-effector solver "
    "(elbows_long_e3.toml; served as shipped)",
    "elbows_long_e8": "the same, 8 epochs (elbows_long_e8.toml)",
    "c15_carry1": "the shipped models served with the whole branch below a dragged joint "
    "turned with its bone (`--serving carry=1`, FABRIK's rigid branch)",
    "placement": "the shipped recipe with the neck, head and collars placed anew on the "
    "autoencoder's and solvers' random bodies (`augment.joint_shift` 1, placement.toml)",
    "ae_cos5e4": "the shipped recipe with the autoencoder at lr 5e-4 decayed along a cosine "
    "(ae_cos5e4.toml)",
    "keep_ends": "the networks of `retry2cm` with the bone pass keeping each targeted wrist and "
    "ankle where the networks put it (`serving.keep_ends`, `--serving keep_ends=true`)",
    "ends_loss": "keep_ends, with both solver banks retrained with it in their losses "
    "(`solver.ends_loss`, ends_loss.toml): shipped since",
    "keep_elbows_serving": "the shipped networks (`ends_loss`) served with each lone targeted "
    "elbow kept too (`serving.keep_elbows`, `--serving keep_elbows=true`)",
    "keep_elbows": "the same with both solver banks retrained with it in their losses "
    "(keep_elbows.toml, `solver.elbows_loss`), on this host's autoencoder: compare "
    "`keep_elbows_here`, which differs in the two elbow solvers only",
    "ends_here": "the `ends_loss` recipe retrained from its seed on this host (runs/ship): "
    "the same seed on another CPU, so the autoencoder's weights differ from the shipped ones "
    "slightly, and every network with them; served "
    "without kept elbows",
    "keep_elbows_here": "`ends_here` served with the lone elbows kept (`serving.keep_elbows`, "
    "as shipped since mx1-39a0a1d79547)",
    "ease5mm": "the shipped models (mx1-39a0a1d79547) served with kept ends eased over 5 mm "
    "(`serving.keep_ease` 0.005, `--serving keep_ease=0.005`)",
    "ease1cm": "the same eased over 1 cm",
    "collar_all": "the shipped models (mx1-39a0a1d79547) served with a kept wrist out of the "
    "arm's reach turning its shoulder about the collar (`serving.keep_collar`, "
    "`--serving keep_collar=true`) in every answer, soft and exact (a first form, in no commit)",
    "collar_soft": "the same in soft answers only (a second form, in no commit)",
    "collar": "the same in answers asked in soft reach with fewer than 5 targets (the turn "
    "search's own): shipped since (mx1-26b6fd5eb17c); exact answers as before, bit for bit",
    "pelvis_1cm": "the shipped models (mx1-26b6fd5eb17c) served with a few-target edit's "
    "pelvis move shortened by 1 cm (`serving.keep_pelvis` 0.01, `--serving keep_pelvis=0.01`)",
    "pelvis_2cm": "the same by 2 cm (shipped as mx1-31d1095cf3e0, taken back: B1 loses)",
    "pelvis_5cm": "the same by 5 cm",
    "pelvis_full": "the same held entirely (`--serving keep_pelvis=1`)",
    "pelvis_all": "the pelvis held entirely in every edit not on it, many targets too (a "
    "`/tmp` form, in no commit)",
    "captured": "mx1-26b6fd5eb17c on edits whose start stays where it was captured "
    "(`--captured`: the pelvis must travel too)",
    "captured_pelvis_1cm": "`pelvis_1cm` on those edits",
    "captured_pelvis_2cm": "`pelvis_2cm` on those edits",
    "captured_pelvis_5cm": "`pelvis_5cm` on those edits",
    "captured_pelvis_full": "`pelvis_full` on those edits",
    "captured_pelvis_all": "`pelvis_all` on those edits (a `/tmp` form; its stress bodies "
    "were put back on the target's pelvis)",
    "pelvis_across": "`pelvis_2cm` held across only (x, z), the height the networks' (a "
    "`/tmp` form)",
    "captured_pelvis_across": "`pelvis_across` on the captured edits, with `pelvis_travel`",
    "captured_travel": "mx1-f16971a84261 (mx1-26b6fd5eb17c with `serving.pelvis_travel`: a "
    "targeted pelvis moves the start across first) on the captured edits: shipped",
    "captured_travel_pelvis_2cm": "`pelvis_travel` with `pelvis_2cm` (mx1-31d1095cf3e0) on the "
    "captured edits",
    "captured_travel_up": "the same with the start moved vertically too (a `/tmp` form)",
    "turn_fit_1cm": "mx1-f16971a84261 with the turn search also trying the start fitted to "
    "the targets (turned and shifted across, least squares; `serving.turn_fit`, "
    "`--serving turn_fit=0.01`), kept if it scores 1 cm below every other candidate",
    "turn_fit_3cm": "the same, kept if 3 cm below",
    "turn_fit_10cm": "the same, kept if 10 cm below: shipped since (mx1-fe4f3722cfd5)",
    "captured_turn_fit_1cm": "`turn_fit_1cm` on the captured edits",
    "captured_turn_fit_3cm": "`turn_fit_3cm` on the captured edits",
    "captured_turn_fit_10cm": "`turn_fit_10cm` on the captured edits",
    "captured_reach_travel": "mx1-3f5e57dad299 (mx1-fe4f3722cfd5 with `serving.reach_travel`: a "
    "target farther across than its chain reaches moves the start across) on the captured "
    "edits: shipped",
    "captured_reach_travel_3d": "the same with the excess measured in 3D (a first form, "
    "dropped: it moved B1)",
    "ae_cos3e3_ends": "the shipped recipe (`ends_loss`) with the autoencoder at lr 3e-3 decayed "
    "along a cosine (ae_cos3e3_ends.toml; both solver banks retrained on it)",
    "solve_mirror": "mx1-a396ee05a58c (mx1-3f5e57dad299 with `serving.solve_mirror`: each pass "
    "also solves the mirror image with the mirrored set's solvers, the mean answered): shipped",
    "captured_solve_mirror": "`solve_mirror` on the captured edits: shipped",
    "retry_polish": "mx1-c34901011fe4 (mx1-a396ee05a58c with `serving.retry_polish`: a soft "
    "answer the retry still leaves more than 2 cm short is polished onto its targets, to "
    "the item's tolerance): shipped",
    "captured_retry_polish": "`retry_polish` on the captured edits: shipped",
    "retry_polish_to_cap": "the same polish stopped within 2 cm of the targets (a `/tmp` form)",
    "captured_retry_polish_to_cap": "`retry_polish_to_cap` on the captured edits",
    "polish_no_retry": "`retry_polish` with the polish in place of the retry's pass (a `/tmp` "
    "form): B1 soft 6.503 -> 6.506",
    "captured_polish_no_retry": "`polish_no_retry` on the captured edits",
    "ae_cos3e3_served": "`ae_cos3e3_ends`'s networks served as mx1-c34901011fe4 (its serving "
    "block set with `pose-trainer serving`): not shipped, the in-studio 5 end effectors lose",
    "turn_quick": "mx1-25bb75ec3824 with `serving.turn_quick`: the turn search scores its "
    "candidates on one pass without the mirror image, then solves the edit as asked "
    "(`--serving turn_quick=true`): not shipped, the in-studio searching sets lose",
    "captured_turn_quick": "`turn_quick` on the captured edits",
    "seed1": "the shipped recipe trained again with seed 1 (trainer/configs/ablation/seed1.toml), "
    "served with the shipped completion networks: the seed's share of every figure",
    "captured_seed1": "`seed1` on the captured edits",
    "seed_pair": "the shipped models and `seed1` together: each pass answers the mean of the "
    "two models' networks (a `/tmp` wrapper of service.networks.answer; twice the networks' "
    "work): not shipped",
    "captured_seed_pair": "`seed_pair` on the captured edits",
    "bones24": "the shipped recipe with random bodies' bones drawn twice as wide "
    "(augment.bone_sigma 0.24, trainer/configs/ablation/bones24.toml), served with the shipped "
    "completion networks: autoencoder closer on held-out bodies, solves no better, in-studio "
    "worse: not shipped",
    "captured_bones24": "`bones24` on the captured edits",
    "latent128": "the shipped recipe with a latent of 128 instead of 64 "
    "(trainer/configs/ablation/latent128.toml), served with the shipped completion networks: "
    "autoencoder closer everywhere, solves no better: not shipped",
    "captured_latent128": "`latent128` on the captured edits",
    "keep_pairs": "mx1-25bb75ec3824 with `serving.keep_pairs`: the hips and the collars "
    "turned, each pair as one rigid part, to the start's angle after the bone pass "
    "(`--serving keep_pairs=true`): not shipped, a held-out set crosses FABRIK the wrong way",
    "captured_keep_pairs": "`keep_pairs` on the captured edits",
    "retry_1mm": "mx1-25bb75ec3824 with `serving.retry_reach` 1 mm instead of 2 cm "
    "(`--serving retry_reach=0.001`; item 46)",
    "retry_2mm": "the same at 2 mm",
    "captured_retry_2mm": "`retry_2mm` on the captured edits",
    "retry_5mm": "the same at 5 mm",
    "fallback": "mx1-25bb75ec3824 with exact reach's fallback after the retry's polish "
    "(`service.retry.polish_short`, item 46)",
    "captured_fallback": "`fallback` on the captured edits",
    "retry_5mm_fallback": "the fallback and the retry at 5 mm: shipped as mx1-3ca9545e56de",
    "captured_retry_5mm_fallback": "`retry_5mm_fallback` on the captured edits",
    "critic_canonical": "mx1-3ca9545e56de with the turn search's completion critic reading "
    "each answer in its own canonical frame, not at the world's yaw (item 47): shipped",
    "captured_critic_canonical": "`critic_canonical` on the captured edits",
    "turn_off": "mx1-3ca9545e56de without the turn search (`--serving turn_yaws=1`; item 48)",
    "ae_cos3e3_c1": "`ae_cos3e3` trained again and served as mx1-3ca9545e56de, the shipped "
    "completion networks copied in (ae_cos3e3_c1.toml; item 48's control)",
    "captured_ae_cos3e3_c1": "`ae_cos3e3_c1` on the captured edits",
    "ae_cos3e3_noise001": "`ae_cos3e3_c1` with each autoencoder step also reconstructing the "
    "batch from latents shaken by 0.01 x each dimension's batch std "
    "(autoencoder.latent_noise, ae_cos3e3_noise001.toml; item 48)",
    "captured_ae_cos3e3_noise001": "`ae_cos3e3_noise001` on the captured edits",
    "ae_cos3e3_noise001_turn_off": "`ae_cos3e3_noise001` without the turn search",
    "ae_cos3e3_noise003": "the same at 0.03 (ae_cos3e3_noise003.toml)",
    "ae_cos3e3_noise005": "the same at 0.05 (ae_cos3e3_noise005.toml)",
    "ae_cos3e3_noise01": "the same at 0.1 (ae_cos3e3_noise01.toml)",
    "captured_ae_cos3e3_noise01": "`ae_cos3e3_noise01` on the captured edits",
    "ae_cos3e3_noise01_long4": "`ae_cos3e3_noise01` with its 5-end-effector solver trained 4 "
    "epochs instead of 8 (ae_cos3e3_noise01_long4.toml)",
    "ae_cos3e3_noise01_long16": "the same, 16 epochs (ae_cos3e3_noise01_long16.toml)",
    "ae_cos3e3_noise005_long_other001": "`ae_cos3e3_noise005` with its 5-end-effector solver "
    "trained with the goal's other joints weighted 0.01 instead of 0.03 "
    "(solver.long_other_weight; item 49)",
    "ae_cos3e3_noise005_long_other010": "the same at 0.1",
    "ae_cos3e3_noise005_long_other030": "the same at 0.3",
    "captured_ae_cos3e3_noise005_long_other030": "`ae_cos3e3_noise005_long_other030` on the "
    "captured edits",
    "ae_cos3e3_noise005_long_other100": "the same at 1.0",
    "ae_cos3e3_noise005_long_other300": "the same at 3.0",
    "long_other030": "the recipe of mx1-3ca9545e56de (mx1_3ca9.toml: its autoencoder and "
    "shared bank) with the 5-end-effector solver's other joints weighted 0.3 "
    "(long_other030.toml; item 49)",
    "captured_long_other030": "`long_other030` on the captured edits",
    "long_other100": "the same at 1.0 (long_other100.toml)",
    "captured_ae_cos3e3_noise005_long_other100": "`ae_cos3e3_noise005_long_other100` on the "
    "captured edits",
    "ae_cos3e3_noise005_other005_long100": "`ae_cos3e3_noise005_long_other100` with the "
    "shared bank's other joints weighted 0.05 instead of 0.03 (solver.other_weight, "
    "ae_cos3e3_noise005_other005_long100.toml; item 50)",
    "ae_cos3e3_noise005_other01_long100": "the same at 0.1 "
    "(ae_cos3e3_noise005_other01_long100.toml)",
    "captured_ae_cos3e3_noise005_other01_long100": "`ae_cos3e3_noise005_other01_long100` on "
    "the captured edits",
    "other01_legs": "`ae_cos3e3_noise005_other01_long100` with only the legs' seven sets "
    "(ankles, knees, feet, both ankles) at 0.1, the others' networks taken from "
    "`ae_cos3e3_noise005_long_other100` (each set's solver trains on its own loss alone; "
    "other01_legs.toml)",
    "other01_arms003": "`ae_cos3e3_noise005_other01_long100` with the arms' five sets "
    "(wrists, elbows, both wrists) at 0.03 (solver.other_weights, other01_arms003.toml), "
    "their networks taken from `ae_cos3e3_noise005_long_other100`: that config's banks, "
    "trained from a copy of that run's autoencoder, by sha256",
    "captured_other01_arms003": "`other01_arms003` on the captured edits",
    "other005_arms003": "the same at 0.05 (the arms at 0.03; other005_arms003.toml): the "
    "shipped recipe on item 48's autoencoder (default.toml retrained from nothing is "
    "mx1-6863ea85cf16, item 50)",
    "captured_other005_arms003": "`other005_arms003` on the captured edits",
    "stay03_quick": "the shipped recipe (mx1-88cd5a3da912, whose 47 solver and autoencoder "
    "files quick_completion.toml gives again by sha256) with the shared bank's stay term at "
    "0.3 instead of 0.1 (solver.stay_weights, stay03_quick.toml; the shipped completion "
    "networks swapped in; item 57)",
    "captured_stay03_quick": "`stay03_quick` on the captured edits",
    "stay10_quick": "the same at 1.0 (stay10_quick.toml)",
    "stay03_legs": "`stay03_quick`'s head, pelvis and legs' sets beside the shipped arms' "
    "sets (scripts/swap_models.py; each set trains on its own loss alone)",
    "captured_stay03_legs": "`stay03_legs` on the captured edits",
    "across_quick": "the shipped recipe with the stay term relative to the pelvis across "
    "(solver.stay_frame across: a body moved across as a whole has stayed put; "
    "across_quick.toml; both banks retrained)",
    "captured_across_quick": "`across_quick` on the captured edits",
    "across03_quick": "`across_quick` with the shared bank's stay term at 0.3 "
    "(across03_quick.toml)",
    "captured_across03_quick": "`across03_quick` on the captured edits",
    "arms_local": "the shipped models with the arms' five sets (wrists, elbows, both wrists) "
    "trained with the stay term on each joint's offset from its parent (solver.stay_frames "
    "local, 0.1; arms_local.toml, its 46 graphs equal by sha256 to the assembled row; "
    "docs/generalisation-3.md item 60)",
    "arms_local03": "the same at 0.3 (arms_local03.toml)",
    "arms_local10": "the same at 1.0 (arms_local10.toml)",
    "arms_across03": "the arms' five sets with the stay term across the pelvis at 0.3 "
    "(arms_across03.toml)",
    "elbows_world10": "the two lone elbows' sets with the stay term in the world at 1.0 "
    "(stay_weights; elbows_world10.toml)",
    "arms_world10": "the arms' five sets so (arms_world10.toml)",
}
COMPLETION = "6-point completion"


@dataclass(frozen=True)
class Row:
    variant: str
    family: str
    soft: float  # mean MPJPE over edit sets (cm), neural soft + bone pass
    exact: float
    fabrik: float
    start: float
    soft_wins: str  # sets where soft < FABRIK
    five_ratio: float  # 5 end effectors: soft / FABRIK
    reach: float  # mean soft reach over edit sets (cm)
    completion: float
    recon: float


def _rows(name: str, data: dict[str, Any], families: list[str] | None) -> list[Row]:
    out = []
    for fam in data["families"]:
        if families is not None and fam["name"] not in families:
            continue
        sets = {k: v for k, v in fam["sets"].items() if k != COMPLETION}
        if not sets:
            continue

        def mean(method: str, key: str = "mpjpe", sets: dict[str, Any] = sets) -> float:
            return float(np.mean([s[method][key] for s in sets.values()]))

        wins = sum(s["neural_bone"]["mpjpe"] < s["fabrik"]["mpjpe"] for s in sets.values())
        five = sets.get("5 end effectors")
        comp = fam["sets"].get(COMPLETION, {}).get("completion", {}).get("mpjpe", float("nan"))
        recon = fam.get("recon") or {}
        out.append(
            Row(
                variant=name,
                family=fam["name"],
                soft=mean("neural_bone"),
                exact=mean("neural_exact"),
                fabrik=mean("fabrik"),
                start=mean("identity"),
                soft_wins=f"{wins}/{len(sets)}",
                five_ratio=(
                    five["neural_bone"]["mpjpe"] / five["fabrik"]["mpjpe"] if five else float("nan")
                ),
                reach=mean("neural_bone", "reach_mean"),
                completion=float(comp),
                recon=float(recon.get("mean", float("nan"))),
            )
        )
    return out


def render(rows: list[Row]) -> str:
    head = (
        "| variant | bodies | start | FABRIK | soft | exact | soft < FABRIK | "
        "5 eff. soft/FABRIK | reach soft | 6-pt | AE recon |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n"
    )
    body = "".join(
        f"| {r.variant} | {r.family} | {r.start:.2f} | {r.fabrik:.2f} | {r.soft:.2f} | "
        f"{r.exact:.2f} | {r.soft_wins} | {r.five_ratio:.2f} | {r.reach:.2f} | "
        f"{r.completion:.2f} | {r.recon:.2f} |\n"
        for r in rows
    )
    legend = "".join(f"- **{k}**: {v}\n" for k, v in VARIANTS.items())
    return (
        "MPJPE to the real pose in cm, mean over the edit sets of a family "
        "(`python -m bench.heldout`); lower is better.\n\n" + head + body + "\n" + legend
    )


def main(
    folder: Annotated[Path, typer.Option(help="Folder of <variant>.json files.")] = Path(
        "reports/ablation"
    ),
    out: Annotated[Path, typer.Option(help="Markdown table to write.")] = Path(
        "reports/ablation.md"
    ),
    family: Annotated[
        list[str] | None, typer.Option(help="Families to show (default: every one).")
    ] = None,
) -> None:
    """Summarise the ablation's held-out results into one markdown table."""
    rows: list[Row] = []
    for name in VARIANTS:
        path = folder / f"{name}.json"
        if path.is_file():
            rows.extend(_rows(name, json.loads(path.read_text()), family))
    fams = " ".join(f'--family "{f}"' for f in family or [])
    text = (
        "# Training ablation on held-out bodies\n\n"
        f"Written by `scripts/ablation.sh` then `python -m bench.ablation {fams}`.\n"
        "`full`, `no_augment`, `no_bodies`, `world_pairs`, `no_delta` and `no_anchor` train at "
        "a small budget (trainer/configs/ablation/full.toml, the recipe of `previous`); every "
        "other row is a full-budget model scored with `python -m bench.heldout --models DIR "
        "[--serving KEY=VALUE ...] --out reports/ablation/NAME.json` (e.g. `passes=3`)."
        " Rows scored with the numpy engine, before the compiled one, agree with it to "
        "5e-14 m (docs/speed.md). A row's config that extends trainer/configs/default.toml "
        "extends it as it was when the row was trained (`git log` of the row's JSON)."
        "\n\n" + render(rows)
    )
    write_atomic(out, text.encode())
    typer.echo(text)


if __name__ == "__main__":
    typer.run(main)
