"""Training configuration: one TOML file, validated; every number of the method lives here."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from core.manifest import Serving
from core.skeleton import BASE_KEYPOINTS, JOINT_NAMES, set_key
from core.text import did_you_mean


class _Section(BaseModel):
    """A section of the config: no unknown keys; every number finite (``allow_inf_nan``:
    ``lr = 1e999``, read by ``tomllib`` as ``inf``, trained with an infinite rate, and
    ``nan`` passed every bound but the serving ones)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Written(float):
    """A TOML float that is no finite number (``1e999``, ``inf``, ``nan``), with the text
    its file writes, so that the message refusing it quotes the file (``tomllib`` reads
    ``1e999`` as ``inf``): :func:`toml_float`. Only ever refused (the schemas take finite
    numbers), it is never a setting."""

    text: str

    def __new__(cls, text: str) -> Written:
        self = super().__new__(cls, text)
        self.text = text
        return self

    def __repr__(self) -> str:
        return self.text

    __str__ = __repr__


def toml_float(text: str) -> float:
    """``tomllib``'s ``parse_float`` for the trainer's TOML files (configs, joint maps): a
    TOML float as ``float()`` reads it (tomllib's own), a non-finite one :class:`Written`."""
    value = float(text)
    return value if math.isfinite(value) else Written(text)


def _check_joints(sets: list[list[str]]) -> list[list[str]]:
    for joints in sets:
        unknown = [j for j in joints if j not in JOINT_NAMES]
        if unknown:
            raise ValueError(f"unknown joints {unknown}")
        if not joints or len(set(joints)) != len(joints):
            raise ValueError(f"a joint set must be non-empty and without repeats: {joints}")
    return sets


#: Learning-rate schedules of a training stage (``trainer.stages.schedule_lr``).
LrSchedule = Literal["constant", "cosine"]


class AutoencoderConfig(_Section):
    hidden: list[int] = Field(default=[200, 200], min_length=1)
    latent: int = Field(default=64, gt=0)
    lr: float = Field(default=1e-4, gt=0)
    batch_size: int = Field(default=256, gt=0)
    epochs: int = Field(default=20, ge=1)
    std_floor: float = Field(default=0.01, gt=0, description="Floor of per-feature std (m).")
    lr_schedule: LrSchedule = Field(
        default="constant", description="Cosine decay of the learning rate to 0 over all steps."
    )
    loss: Literal["mse", "mpjpe"] = Field(
        default="mse",
        description="Reconstruction loss: MSE of the normalised coordinates, or the mean "
        "per-joint distance in metres (MPJPE, what the benchmarks score).",
    )
    latent_noise: float = Field(
        default=0.0,
        ge=0.0,
        description="Each step also reconstructs the batch from latents shaken by Gaussian "
        "noise of this many times each latent dimension's batch std, and adds that loss: a "
        "decoder smooth around real poses' codes, where the solvers move them. 0 = off.",
    )


def _serving(name: str) -> Any:
    """The manifest's own field ``serving.<name>`` (default, bounds, description), for a
    setting the trainer only passes on to the manifest."""
    return Serving.model_fields[name]


class SolverConfig(_Section):
    hidden: list[int] = Field(default=[126, 126, 126], min_length=1)
    residual: bool = Field(default=True, description="Output z + f(z, targets).")
    delta: bool = Field(
        default=True,
        description="Answer start + D(z') - D(z) (trained and served so); False: D(z').",
    )
    anchor: bool = Field(
        default=True,
        description="With delta: answer start + D(S(z, t)) - D(S(z, x_t)) (trained and served "
        "so): what the solver does when asked to stay put is subtracted.",
    )
    lr: float = Field(default=1e-4, gt=0)
    batch_size: int = Field(default=256, gt=0)
    epochs: int = Field(default=5, ge=1)
    max_gap_seconds: float = Field(default=1.0, gt=0)
    other_weight: float = Field(default=0.01, ge=0)
    stay_weight: float = Field(
        default=0.0,
        ge=0,
        description="Weight of MSE(non-target joints - their start positions): the joints "
        "not asked for move as little as the targets allow.",
    )
    stay_frame: Literal["world", "local", "across"] = Field(
        default="world",
        description="Where the stay term measures how far a joint not asked for moved: its "
        "world position; its offset from its parent joint (the root: its position), so "
        "that a joint carried along by a moved parent, as FABRIK carries it, has stayed put; "
        "or its place relative to the pelvis across (x, z), so that a body that travels "
        "across as a whole has stayed put (its height and shape have not).",
    )
    bone_weight: float = Field(
        default=1.0,
        ge=0,
        description="Weight of MSE(decoded bone lengths - start bone lengths); 0 = the paper.",
    )
    rigid_loss: bool = Field(
        default=False,
        description="Measure the joint losses on the answer after the service's bone pass "
        "to the start's bone lengths (trainer.rigid), i.e. on what is served; False: on the "
        "decoded answer.",
    )
    joint_loss: Literal["mse", "distance"] = Field(
        default="mse",
        description="How the joint terms (targets, other joints, stay) measure an answer: "
        "mean squared coordinate error, or mean per-joint distance (what MPJPE and reach "
        "score; it tolerates a few joints moving far less than many moving a little).",
    )
    # Serving settings, written to the manifest's `serving` block: defined there, once
    # (core.manifest.Serving); the solvers are not trained differently for them.
    passes: int = _serving("passes")
    carry: float = _serving("carry")
    turn_yaws: int = _serving("turn_yaws")
    turn_margin: float = _serving("turn_margin")
    turn_min_targets: int = _serving("turn_min_targets")
    turn_plausibility: float = _serving("turn_plausibility")
    turn_critic: Literal["autoencoder", "completion"] = _serving("turn_critic")
    turn_fit: float = _serving("turn_fit")
    turn_quick: bool = _serving("turn_quick")
    turn_gate: float = _serving("turn_gate")
    retry_reach: float = _serving("retry_reach")
    retry_polish: bool = _serving("retry_polish")
    keep_ends: bool = _serving("keep_ends")
    keep_elbows: bool = _serving("keep_elbows")
    keep_ease: float = _serving("keep_ease")
    bend_side: float = _serving("bend_side")
    keep_collar: bool = _serving("keep_collar")
    keep_feet: bool = _serving("keep_feet")
    critic_fabrik: float = _serving("critic_fabrik")
    keep_pairs: bool = _serving("keep_pairs")
    keep_pelvis: float = _serving("keep_pelvis")
    pelvis_travel: bool = _serving("pelvis_travel")
    reach_travel: bool = _serving("reach_travel")
    solve_mirror: bool = _serving("solve_mirror")
    # (their names: SERVING_SETTINGS, below, which the export and the checkpoint tags read)
    carry_loss: bool = Field(
        default=False,
        description="With rigid_loss: the losses also see the carry below the targets "
        "(`carry`), as the answer is served (then `carry` is a training setting too).",
    )
    ends_loss: bool = Field(
        default=False,
        description="With rigid_loss: the losses also see the targeted limb ends kept where "
        "the network put them (`keep_ends`), as the answer is served (then `keep_ends` is a "
        "training setting too).",
    )
    elbows_loss: bool = Field(
        default=False,
        description="With ends_loss: the losses also see the targeted elbows kept "
        "(`keep_elbows`; then it is a training setting too). Off, the elbows are kept in "
        "serving only (the shipped recipe; docs/generalisation-serving.md item 29).",
    )
    identity_fraction: float = Field(
        default=0.1,
        ge=0,
        lt=1,
        description="Share of pairs whose target is the start pose itself (solvers learn to "
        "leave a satisfied pose alone, which repeated passes and drags rely on).",
    )
    sets: list[list[str]] = Field(
        default=[
            ["head"],
            ["pelvis"],
            ["left_wrist"],
            ["right_wrist"],
            ["left_elbow"],
            ["right_elbow"],
            ["left_ankle"],
            ["right_ankle"],
            ["left_knee"],
            ["right_knee"],
            ["left_foot"],
            ["right_foot"],
            ["left_wrist", "right_wrist"],
            ["left_ankle", "right_ankle"],
        ]
    )

    long_sets: list[list[str]] = Field(
        default=[],
        description="Sets trained apart, in a bank of their own, for long_epochs: a set of "
        "many targets keeps improving past the one epoch after which single joints drift.",
    )
    long_epochs: int = Field(default=8, ge=1)
    long_other_weight: float | None = Field(
        default=None,
        ge=0,
        description="other_weight for the long_sets' bank alone (None: other_weight).",
    )
    other_weights: dict[str, Annotated[float, Field(ge=0)]] = Field(
        default={},
        description="other_weight of single sets of `sets`, by key (the set's joints sorted "
        "and joined by '+', as the manifest names it); the other sets: other_weight (a key "
        "of no set of `sets`, a long_sets one too, weighs nothing and is in no checkpoint "
        "tag: a config that changes the sets inherits them). "
        "Each set's solver is trained on its own loss alone: a set's weight changes no other.",
    )

    stay_weights: dict[str, Annotated[float, Field(ge=0)]] = Field(
        default={},
        description="stay_weight of single sets of `sets`, by key, as other_weights (the long "
        "bank and the other sets: stay_weight).",
    )

    stay_frames: dict[str, Literal["world", "local", "across"]] = Field(
        default={},
        description="stay_frame of single sets of `sets`, by key, as other_weights (the long "
        "bank and the other sets: stay_frame): the arms' sets can hold a wrist carried by a "
        "moved elbow where its parent put it while the rest hold the world.",
    )

    _v = field_validator("sets", "long_sets")(_check_joints)

    @field_validator("sets", "long_sets")
    @classmethod
    def _once(cls, sets: list[list[str]]) -> list[list[str]]:
        """Each set once (its joints in any order): a set listed twice trained every stage,
        then the export failed ("model names must be unique"; a studio audit, D9)."""
        seen: set[str] = set()
        for joints in sets:
            if (key := set_key(joints)) in seen:
                raise ValueError(f"{joints} listed twice (a set's joints in any order)")
            seen.add(key)
        return sets

    def weight_of(self, joints: list[str], long: bool = False) -> float:
        """The weight of the goal's other joints the solver of ``joints`` trains with: the
        long bank's (``long``) ``long_other_weight``, a shared set's its ``other_weights``
        entry; else ``other_weight``. The trainer and the checkpoint tags read it here."""
        if long:
            return self.other_weight if self.long_other_weight is None else self.long_other_weight
        return self.other_weights.get(set_key(joints), self.other_weight)

    def unused_weights(self) -> list[str]:
        """The ``other_weights``, ``stay_weights`` and ``stay_frames`` keys that name no set
        of ``sets`` (ignored, and in no checkpoint tag, so that a config changing the sets
        inherits them; a typo would train the baseline unsaid: the trainer warns of them)."""
        trained = {set_key(s) for s in self.sets}
        own = (
            ("other_weights", self.other_weights),
            ("stay_weights", self.stay_weights),
            ("stay_frames", self.stay_frames),
        )
        return [f"{name}.{key}" for name, weights in own for key in weights if key not in trained]

    def stay_of(self, joints: list[str], long: bool = False) -> float:
        """The stay term's weight the solver of ``joints`` trains with: a shared set's
        ``stay_weights`` entry, else ``stay_weight``."""
        if long:
            return self.stay_weight
        return self.stay_weights.get(set_key(joints), self.stay_weight)

    def frame_of(self, joints: list[str], long: bool = False) -> str:
        """The frame the stay term of the solver of ``joints`` is measured in: a shared
        set's ``stay_frames`` entry, else ``stay_frame``."""
        if long:
            return self.stay_frame
        return self.stay_frames.get(set_key(joints), self.stay_frame)

    @model_validator(mode="after")
    def _apart(self) -> SolverConfig:
        both = {tuple(sorted(j)) for j in self.sets} & {tuple(sorted(j)) for j in self.long_sets}
        if both:
            raise ValueError(f"solver sets in both sets and long_sets: {sorted(both)}")
        own = (
            ("other_weights", self.other_weights),
            ("stay_weights", self.stay_weights),
            ("stay_frames", self.stay_frames),
        )
        for name, weights in own:
            for key in weights:  # joints sorted, joined by '+': the manifest's key
                _check_joints([key.split("+")])
                if key != set_key(key.split("+")):
                    raise ValueError(f"{name}: {key!r} is not a set's key (sorted joints)")
        return self


#: The solver section's serving settings (``_serving``): passed on to the manifest's
#: ``serving`` block under the same names, and not in the solvers' checkpoint tags.
SERVING_SETTINGS: tuple[str, ...] = (
    "passes", "carry", "turn_yaws", "turn_margin", "turn_min_targets", "turn_plausibility",
    "turn_critic", "turn_fit", "turn_quick", "turn_gate", "retry_reach", "retry_polish",
    "keep_ends", "keep_elbows", "keep_ease", "bend_side", "keep_collar", "keep_pairs",
    "keep_pelvis", "pelvis_travel", "reach_travel", "solve_mirror", "critic_fabrik",
    "keep_feet",
)  # fmt: skip
if not set(SERVING_SETTINGS) <= set(SolverConfig.model_fields) & set(Serving.model_fields):
    raise RuntimeError("SERVING_SETTINGS must name fields of SolverConfig and of Serving")


def seen_by_losses(solver: Mapping[str, Any]) -> tuple[str, ...]:
    """The serving settings the solvers' losses saw, from a ``solver`` section (a dumped
    :class:`SolverConfig`, or an older one without some flags: those off): training
    settings too, so in the checkpoint tags, and fixed once trained."""
    ends = bool(solver.get("ends_loss", False))
    return (
        (("carry",) if solver.get("carry_loss", False) else ())
        + (("keep_ends",) if ends else ())
        + (("keep_elbows",) if ends and solver.get("elbows_loss", False) else ())
    )


class CompletionConfig(_Section):
    schemes: list[list[str]] = Field(
        default=[
            list(BASE_KEYPOINTS),
            ["head", "left_elbow", "right_elbow", "left_knee", "right_knee"],
            ["spine2", "left_shoulder", "right_shoulder", "left_foot", "right_foot"],
        ],
        description="Nested schemes: level n's key points are the union of the first n lists.",
    )
    hidden: list[int] = Field(default=[300, 400, 300, 200], min_length=1)
    activation: Literal["selu", "relu"] = "selu"
    lr: float = Field(default=1e-3, gt=0)
    lr_schedule: LrSchedule = Field(
        default="cosine", description="Cosine decay of the learning rate to 0 over all steps."
    )
    weight_decay: float = Field(default=1e-5, ge=0, description="L2 regularisation.")
    batch_size: int = Field(default=256, gt=0)
    epochs: int = Field(default=6, ge=1)
    loss: Literal["mse", "mpjpe"] = Field(
        default="mse",
        description="Training loss: mean squared coordinate error, or the mean per-joint "
        "distance (MPJPE, what the benchmarks score; where key points leave a joint "
        "ambiguous it pulls towards the likeliest place, not the mean of the places).",
    )
    mirror: bool = True
    yaw: bool = True
    serving_yaws: int = Field(
        default=1,
        ge=1,
        le=16,
        description="Serving (manifest serving.completion_yaws): the answer is the mean over "
        "this many turns of the key points about +Y.",
    )
    serving_mirror: bool = Field(
        default=False,
        description="Serving (manifest serving.completion_mirror): also over each turn's "
        "mirror image.",
    )
    fill_probability: float = Field(
        default=0.5,
        ge=0,
        le=1,
        description="Chance that an optional key point of level n>1 is replaced, in "
        "training, by the previous level's prediction (as at serving time).",
    )

    _v = field_validator("schemes")(_check_joints)

    @field_validator("schemes")
    @classmethod
    def _nested(cls, schemes: list[list[str]]) -> list[list[str]]:
        if sorted(schemes[0]) != sorted(BASE_KEYPOINTS):
            raise ValueError(f"scheme 1 must be the six base points {list(BASE_KEYPOINTS)}")
        seen: set[str] = set()
        for level in schemes:
            if seen & set(level):
                raise ValueError(f"schemes repeat joints: {sorted(seen & set(level))}")
            seen |= set(level)
        return schemes

    def level_joints(self, level: int) -> list[str]:
        """Key points of level ``level`` (1-based): the union of the first ``level`` lists."""
        out: list[str] = []
        for joints in self.schemes[:level]:
            out.extend(joints)
        return out


class AugmentConfig(_Section):
    """Training-time variety of bodies, facing and frames (``trainer/augment.py``)."""

    body_fraction: float = Field(
        default=0.8, ge=0, le=1, description="Share of samples rebuilt on a random body."
    )
    bone_sigma: float = Field(default=0.12, ge=0, description="Log-normal sigma per bone.")
    limb_sigma: float = Field(default=0.05, ge=0, description="Log-normal sigma per body.")
    symmetric_fraction: float = Field(default=0.5, ge=0, le=1)
    min_scale: float = Field(default=0.6, gt=0)
    max_scale: float = Field(default=1.6, gt=0)
    pelvis_shift: float = Field(
        default=0.35, ge=0, description="Pelvis moved up to this share of pelvis->spine1."
    )
    joint_shift: float = Field(
        default=0.0,
        ge=0,
        description="Autoencoder and solver pairs: the neck, head and collars moved along "
        "their parent bones by up to this times core.bodies.PLACEMENT's limits (1: the "
        "stress set's range); 0: the pelvis alone is placed anew. Completion does not read it.",
    )
    mirror: bool = True
    normalise_size: bool = Field(
        default=True,
        description="Scale every body to the reference total bone length (the service does "
        "the same), instead of the old nearest-training-skeleton scale.",
    )
    yaw_sigma_deg: float = Field(
        default=25.0, ge=0, description="Autoencoder: random facing of a pose (goals turn)."
    )
    offset_fraction: float = Field(default=0.3, ge=0, le=1)
    offset_sigma: float = Field(default=0.08, ge=0, description="Autoencoder: floor offset (m).")
    align_pelvis: float = Field(
        default=0.5, ge=0, le=1, description="Pairs: start moved onto the goal's pelvis."
    )
    align_floor: float = Field(
        default=0.3, ge=0, le=1, description="Pairs: start moved onto the goal's floor point."
    )
    world_pairs: bool = Field(
        default=True,
        description="Pairs in the start's frame (False: both canonicalised, the old way).",
    )
    lift_start: float = Field(
        default=0.0,
        ge=0,
        le=1,
        description="Canonicalised pairs (world_pairs false): the share of pairs whose start "
        "is lifted onto the goal's pelvis height, as a world-space edit made on the goal's "
        "pelvis has it (both pelvises then coincide; facing still canonical apart).",
    )
    enabled: bool = Field(default=True, description="False: no augmentation at all.")


#: The ONNX opsets the export writes (``TrainConfig.opset``): torch 2.13's exporter has
#: implementations for 18 to 25; it "converts" a graph to any other, and below 18 that fails
#: (the files stay opset 18). ``trainer.export`` checks every file's opset all the same.
OPSETS: tuple[int, int] = (18, 25)


class TrainConfig(_Section):
    seed: int = 0
    threads: int = Field(
        default=1, ge=1, description="torch intra-op threads (results depend on it)."
    )
    dataset: str = "data/poses.npz"
    run_dir: str = "runs/default"
    out_dir: str = "models"
    opset: int = Field(
        default=18,
        description=f"ONNX opset of the exported graphs: {OPSETS[0]} to {OPSETS[1]}, the "
        "ones torch's exporter writes itself.",
    )
    max_train_frames: int | None = Field(
        default=None,
        ge=1,
        description="Cap, for smoke runs: whole clips in a seeded order, the clip that "
        "crosses the cap kept (so a few long clips may exceed it); None: every frame.",
    )
    max_eval_frames: int = Field(
        default=20000, ge=1, description="Cap of the frames and pairs each evaluation reads."
    )
    accept_implausible: bool = Field(
        default=False,
        description="Train on a dataset whose poses look implausible for their map (a thigh "
        "outside 0.2-0.7 m: the `unit`?; the head not over the pelvis: the `up_axis`?; "
        "trainer.data.checks.implausible), which training otherwise refuses.",
    )
    autoencoder: AutoencoderConfig = AutoencoderConfig()
    solver: SolverConfig = SolverConfig()
    completion: CompletionConfig = CompletionConfig()
    augment: AugmentConfig = AugmentConfig()

    @field_validator("opset")
    @classmethod
    def _opset(cls, opset: int) -> int:
        """One the export writes: below 18 torch's exporter wrote opset 18 anyway after ~35
        tracebacks of a failed conversion, exited 0, and the manifest named the opset asked
        for (a studio audit, D5); above the range its conversion is untested."""
        if not OPSETS[0] <= opset <= OPSETS[1]:
            raise ValueError(f"the export writes ONNX opsets {OPSETS[0]} to {OPSETS[1]}")
        return opset


def _read_toml(path: Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """A config file's table; ``extends = "other.toml"`` (relative to the file) loads that
    file first and overrides it section by section, so a variant states only its change."""
    path = path.resolve()
    if path in seen:
        raise ValueError(f"{path}: 'extends' loops back to itself")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh, parse_float=toml_float)
    except FileNotFoundError:
        via = f" (extends = in {seen[-1]}: a path relative to that file's folder)" if seen else ""
        raise ValueError(f"{path}: no such config file{via}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not TOML: {exc}") from None
    parent = data.pop("extends", None)
    if parent is None:
        return data
    base = _read_toml(path.parent / str(parent), (*seen, path))
    return _merge(base, data)


def _config_errors(path: Path | str | None, exc: ValidationError) -> ValueError:
    """pydantic's errors as one line naming the file, each field and, for a key that is
    not a setting, the setting of its section it is a slip of (:func:`core.text.near_name`)."""
    parts = []
    for e in exc.errors(include_url=False):
        where = ".".join(str(x) for x in e["loc"])
        message = str(e["msg"])
        if e["type"] == "extra_forbidden":
            model: type[BaseModel] = TrainConfig
            for key in e["loc"][:-1]:
                field = model.model_fields.get(str(key))
                annotation = field.annotation if field is not None else None
                if not (isinstance(annotation, type) and issubclass(annotation, BaseModel)):
                    break
                model = annotation
            message = "not a setting" + did_you_mean(str(e["loc"][-1]), model.model_fields)
        elif isinstance(e["input"], int | float) and not isinstance(e["input"], bool):
            message += f", got {e['input']!r}"  # (a Written: 1e999, as the file writes it)
        parts.append(f"{where}: {message}")
    return ValueError(f"{path or 'the defaults'}: " + "; ".join(parts))


def _merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = {**out[key], **value}
        else:
            out[key] = value
    return out


def load_config(path: Path | str | None, overrides: dict[str, Any] | None = None) -> TrainConfig:
    """Load a TOML config (or the defaults), then apply ``overrides`` (shallow per section)."""
    data: dict[str, Any] = {} if path is None else _read_toml(Path(path))
    try:
        return TrainConfig.model_validate(_merge(data, overrides or {}))
    except ValidationError as exc:
        raise _config_errors(path, exc) from None


#: The shipped models' recipe (``extends`` it: the fields' defaults here are the paper's).
DEFAULT_TOML: Path = Path(__file__).resolve().parent / "configs" / "default.toml"


def recipe_warning(path: Path | str | None, out_dir: str = "") -> str | None:
    """What a run without ``--config``, or with a config that ``extends`` nothing, trains
    (the fields' built-in defaults: the paper's recipe, 35 settings from the shipped models'
    ``default.toml``), said (a studio audit, D13: it went without a word); ``out_dir``: the
    run's, named where it is the shipped ``models``."""
    shipped = f'extends = "<path>/{DEFAULT_TOML.relative_to(DEFAULT_TOML.parents[2])}"'
    if path is None:
        into = (
            ", exporting into models (the shipped models folder, which the export replaces)"
            if Path(out_dir) == Path("models")
            else ""
        )
        return (
            "no --config: training the built-in defaults of trainer/config.py (the paper's "
            "recipe, not trainer/configs/default.toml's, the shipped models')"
            f"{into}; give a config of your own that starts with {shipped}"
        )
    try:
        with Path(path).open("rb") as fh:
            extends = "extends" in tomllib.load(fh, parse_float=toml_float)
    except (OSError, tomllib.TOMLDecodeError):
        return None  # (load_config says why)
    if extends or Path(path).resolve() == DEFAULT_TOML:
        return None
    return (
        f"{path} has no `extends`: the settings it leaves out take the built-in defaults of "
        "trainer/config.py (the paper's recipe), not trainer/configs/default.toml's (the "
        f"shipped models'); to train the shipped recipe, start it with {shipped}"
    )


#: Overrides of ``--quick``: a smoke run of every stage (its training a few seconds; with the
#: evaluation and export about a minute: 60 s wall on 2 cores, 2026-12-07).
QUICK: dict[str, Any] = {
    "max_train_frames": 4000,
    "max_eval_frames": 1000,
    "autoencoder": {"epochs": 2},
    "solver": {"epochs": 1, "long_epochs": 1},
    "completion": {"epochs": 1},
}
