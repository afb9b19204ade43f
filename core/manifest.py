"""The model manifest: one versioned schema, written by the trainer, validated on load.

``models/manifest.json`` describes the skeleton the models were trained for, how poses
are normalised (inside the exported graphs) and every ONNX file with its sha256, its
inputs and outputs, its kind and target joint set, and where it came from.

Schema version 1. Kinds:

* ``autoencoder`` (``part`` = ``encoder``: ``pose [N,63] -> latent [N,D]``;
  ``part`` = ``decoder``: ``latent [N,D] -> pose [N,63]``). Poses are canonical,
  metres, joint-major (x, y, z per joint in skeleton order).
* ``solver``: ``latent [N,D], targets [N,3k] -> solved_latent [N,D]``; ``joints`` lists the k
  target joints in the order of the ``targets`` input; ``key`` is the sorted set key.
* ``completion``: ``keypoints [N,3k] -> pose [N,63]``; ``joints`` lists the key points,
  ``level`` orders the nested schemes (1 = the six base points).
* ``fused`` (optional): ``pose [N,63], targets [N,3k] -> solved_pose [N,63]``, one solver's whole
  edit in one graph (encoder, solver, decoder; with ``serving.delta`` the answer
  ``pose + D(z') - D(z)``), fused at export time so the service needs no ``onnx``.
* ``mirror`` (optional): ``pose [N,63], targets [N,3k] -> solved_pose [N,63]``, the mean of
  a fused graph's answer and its mirror set's fused answer to the mirrored pose and
  targets, taken back (``serving.solve_mirror`` in one run; ``trainer.mirror``). Each
  needs its set's fused graph and its mirror set's.

:func:`write_manifest` records the sha256 of the content it writes (``content_sha256``);
:func:`load_manifest` serves a manifest whose content differs (edited by hand) under a
version of its content (:func:`served_version`), so that answers that changed are not named
by the version of the models as written.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    model_validator,
)

from core.io import sha256_file, write_atomic
from core.skeleton import (
    FRAME,
    JOINT_INDEX,
    JOINT_NAMES,
    MIRROR,
    NUM_JOINTS,
    PARENT_NAMES,
    mirror_key,
    set_key,
)

SCHEMA_VERSION = 1
MANIFEST_NAME = "manifest.json"


class ManifestError(Exception):
    """The manifest or one of its model files is missing, malformed or tampered with."""

    def __init__(self, path: Path | str, reason: str) -> None:
        super().__init__(f"{path}: {reason}")
        self.path = str(path)
        self.reason = reason

    def __reduce__(self) -> tuple[Any, ...]:
        """Pickled as its arguments (``args`` holds the one message ``__init__`` does not
        take: unpickling it was a TypeError), its fields as they are."""
        return type(self), (self.path, self.reason), self.__dict__


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class TensorSpec(_Strict):
    name: str
    shape: list[int | str]
    dtype: Literal["float32"] = "float32"


class SkeletonSpec(_Strict):
    joints: list[str]
    parents: list[str | None]
    reference_bone_lengths: dict[str, float] = Field(
        description="Mean length (m) of the bone ending at each non-root joint, train split."
    )
    frame: dict[str, str]
    skeletons: list[list[float]] = Field(
        min_length=1,
        description="The body shapes of the training data: bone lengths (m, BONES order) "
        "of each distinct skeleton with at least 1% of the training frames. A request's "
        "character is scaled to the one whose proportions it matches best.",
    )

    @model_validator(mode="after")
    def _matches_canonical(self) -> SkeletonSpec:
        if tuple(self.joints) != JOINT_NAMES:
            raise ValueError("skeleton joints differ from the canonical skeleton")
        if self.parents != [PARENT_NAMES[j] for j in JOINT_NAMES]:
            raise ValueError("skeleton parents differ from the canonical skeleton")
        expected = {j for j in JOINT_NAMES if PARENT_NAMES[j] is not None}
        if set(self.reference_bone_lengths) != expected:
            raise ValueError("reference_bone_lengths must name every non-root joint")
        if any(not (0.0 < v < 2.0) for v in self.reference_bone_lengths.values()):
            raise ValueError("reference bone lengths must be in (0, 2) metres")
        if any(len(s) != len(expected) or min(s) <= 0.0 for s in self.skeletons):
            raise ValueError(f"each skeleton needs {len(expected)} positive bone lengths")
        if self.frame != FRAME:
            raise ValueError(f"frame conventions differ from {FRAME}")
        return self


class Normalisation(_Strict):
    """Per-feature statistics of the train split; applied inside the exported graphs."""

    inside_graphs: Literal[True] = True
    mean: list[float] = Field(min_length=3 * NUM_JOINTS, max_length=3 * NUM_JOINTS)
    std: list[float] = Field(min_length=3 * NUM_JOINTS, max_length=3 * NUM_JOINTS)
    std_floor: float = Field(gt=0)


class Serving(_Strict):
    """How the engine must feed the networks (fixed by how they were trained). Every
    number finite and in its bounds: the one check of a manifest's block, a trainer
    config's serving settings (``trainer.config``, whose fields are these) and an engine's
    overrides (:func:`serving_with`)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)

    body: Literal["nearest_skeleton", "total_length"] = Field(
        default="nearest_skeleton",
        description="How a character is sized for the networks: scaled to the training "
        "skeleton it matches best in proportions (`nearest_skeleton`), or so that its total "
        "bone length equals the reference skeleton's (`total_length`; networks trained on "
        "many random bodies).",
    )
    delta: bool = Field(
        default=False,
        description="The solved pose is start + D(z') - D(z) (the autoencoder's error on the "
        "start pose left out) instead of D(z').",
    )
    anchor: bool = Field(
        default=False,
        description="With delta: subtract what the solver does when asked to stay put, "
        "start + D(S(z, t)) - D(S(z, x_t)), so an edit that asks for no change changes "
        "nothing and the network's bias never reaches the answer.",
    )
    carry: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="After the bone pass, every joint below a targeted joint (not the root) "
        "with no target of its own below turns with the targeted joint's bone, as a rigid "
        "branch would, by this fraction: 0 keeps the network's answer, 1 carries the branch "
        "as the start pose had it (as FABRIK does); each bone's direction is the mix.",
    )
    keep_ends: bool = Field(
        default=False,
        description="After the bone pass (and the carry), each targeted wrist and ankle with "
        "no target on its elbow or knee, shoulder or hip, or below it goes back where the "
        "networks put it (as near as the limb reaches), its elbow or knee placed anew with "
        "the character's own lengths in the plane the limb was bent in (core.ends).",
    )
    keep_elbows: bool = Field(
        default=False,
        description="The same for each targeted elbow with no target on its shoulder or "
        "collar or below it (the wrist): back where the networks put it (as near as the "
        "collar bone and the upper arm reach), its shoulder placed anew with the "
        "character's own lengths, the forearm and hand moved with it (core.ends).",
    )
    keep_ease: float = Field(
        default=0.0,
        ge=0.0,
        le=0.1,
        description="With keep_ends / keep_elbows: an end the bone pass left g metres from "
        "where the networks put it, g below this, goes back only g / keep_ease of the way "
        "(0: all the way), so that a millimetre of the networks' answer does not bend a "
        "straight limb (core.ends).",
    )
    bend_side: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="With keep_ends: where the networks drew a kept limb bent less than "
        "this fraction of the bend the character's own lengths need, its elbow or knee "
        "turns towards the side elbows and knees bend to in the training poses (out, down "
        "and back; forward), the more the straighter, so that the side does not turn round "
        "between two nearly equal edits (0: the networks' plane alone; core.ends).",
    )
    critic_fabrik: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="A neural answer (bone lengths kept) that the turn search's critic finds "
        "more than this many metres (mean per joint) further from a real body than FABRIK's "
        "answer to the same edit from the caller's start, FABRIK's reaching every target "
        "and pin within the item's tolerance, is replaced by FABRIK's (its solvers end with "
        "`fabrik-critic`; service.fallback). 0: never.",
    )
    keep_pairs: bool = Field(
        default=False,
        description="After the bone pass, the two hips on the pelvis and the two collars on "
        "the chest, where the networks put them nearer each other than 80 % of their "
        "distance in the start, turn, each pair as one rigid part, to the angle they make in "
        "the start pose (the body's width between them kept), facing as the networks put "
        "them, the legs and arms moved with them (core.rigid).",
    )
    keep_feet: bool = Field(
        default=False,
        description="With the bone pass: a leg none of whose hip, knee, ankle and foot is a "
        "target or pin, whose ankle or foot the answer puts below the floor (or below the "
        "lower of the two in the start, where that is lower), has its ankle and foot raised "
        "back by what the lower sank, the hip where it is and the knee bent to fit, as far "
        "as the leg folds: a pelvis dragged down crouches the body instead of sinking its "
        "feet (core.compiled_limbs.floor_item).",
    )
    keep_collar: bool = Field(
        default=False,
        description="With keep_ends, in answers asked in soft reach with fewer than "
        "turn_min_targets targets (exact reach has its FABRIK polish, and its soft passes "
        "before it go without; more targets search the body's turn): "
        "a kept wrist whose place lies beyond the arm's reach from its shoulder first turns "
        "the shoulder about its collar towards it, as little as brings it within reach, the "
        "arm moving with it (core.ends).",
    )
    keep_pelvis: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="In answers of fewer than turn_min_targets targets, none on the pelvis: "
        "the networks' move of the pelvis away from the start's loses this many metres of "
        "its length (a shorter move is dropped) before the bone pass lays the body out "
        "from it, so a few-joint edit does not drift the hips (0: off; core.compiled).",
    )
    pelvis_travel: bool = Field(
        default=False,
        description="In a neural edit with a target on the pelvis and no pins, the start "
        "is first moved horizontally so that its pelvis lies over that target (the "
        "networks, trained on poses canonicalised over their pelvis, move it up or down "
        "but not across); the height stays the networks' to change.",
    )
    reach_travel: bool = Field(
        default=False,
        description="In a neural edit of fewer than turn_min_targets targets and no pins, "
        "a target farther across (x, z) from the start's pelvis than its chain reaches "
        "first moves the start across by the excess (the farthest such target's), as a "
        "body steps towards what it cannot reach.",
    )
    turn_yaws: int = Field(
        default=1,
        ge=1,
        le=36,
        description="Turn search (service.turns): a neural edit with at least "
        "`turn_min_targets` targets and no pins is first tried from its start turned about "
        "the vertical through the pelvis by this many evenly spaced yaws (0 first), and "
        "solved from the one whose soft answer scores lowest (reach, and with "
        "`turn_plausibility` the answer's distance to the pose space). 1 = off.",
    )
    turn_margin: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="Metres by which a turned start's answer must land nearer the targets "
        "(mean distance) than the unturned one's to be chosen; at the networks' body size "
        "(scores are scaled with each body as the networks see it, so is `turn_fit`).",
    )
    turn_plausibility: float = Field(
        default=0.0,
        ge=0.0,
        le=100.0,
        description="The turn search scores a candidate by its targets' mean distance plus "
        "this times the mean distance of its answer to `turn_critic`'s idea of it.",
    )
    turn_critic: Literal["autoencoder", "completion"] = Field(
        default="autoencoder",
        description="What the turn search's plausibility term compares a candidate answer "
        "with: the autoencoder's round trip of it (`autoencoder`), or the body completion "
        "level 1 builds from the answer's own base key points (`completion`: how far the "
        "answer is from a body those points imply).",
    )
    turn_min_targets: int = Field(
        default=5, ge=1, le=21, description="The fewest targets an edit needs to search."
    )
    turn_fit: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="The turn search also tries the start moved to fit its targets: turned "
        "about the vertical and shifted across by the rigid motion that best carries its "
        "targeted joints onto their targets (least squares, heights left alone), for a body "
        "that has travelled as well as turned. Kept only if it scores this many metres "
        "below every other candidate (0: not tried).",
    )
    turn_gate: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="Metres, at the networks' body size (as `turn_margin`): an edit searches "
        "the turn only if its targets lie at least this far across (x, z) from the joints "
        "they are for, on average; nearer, the edit asks for no turn of the body and is "
        "solved from its start (0: every edit that may search does).",
    )
    turn_quick: bool = Field(
        default=False,
        description="The turn search solves its candidates in their quick form, one pass "
        "without the mirror image, then the edit as asked from the start it keeps: a "
        "quarter of the candidates' networks' work, and candidates scored on rougher "
        "answers (docs/generalisation-serving-2.md item 40).",
    )
    retry_reach: float = Field(
        default=0.0,
        ge=0.0,
        le=1.0,
        description="A soft neural answer (bone lengths kept) whose farthest target is more "
        "than this many metres away after its passes gets one more pass from that answer "
        "(service.engine: the edits the passes left short, and only they); metres at the "
        "networks' body size, scaled with each body as the networks see it (a character "
        "twice the size: twice as far); 0 = never.",
    )
    retry_polish: bool = Field(
        default=False,
        description="A soft answer still more than `retry_reach` from a target after that "
        "pass is polished onto its targets (FABRIK from the answer, the trunk held first, "
        "to the item's tolerance), as exact reach is: a soft answer then never misses by "
        "more than `retry_reach`. Off, or with `retry_reach` 0: the networks' answer as is.",
    )
    passes: int = Field(
        default=1,
        ge=1,
        le=8,
        description="Neural solves per edit: each pass after the first starts from the "
        "previous pass's answer (bone lengths restored, canonicalised anew) with the same "
        "targets, so what the bone pass took from the reach is asked for again.",
    )
    solve_mirror: bool = Field(
        default=False,
        description="Each neural pass also solves the edit's mirror image (left and right "
        "swapped, x -> -x in the canonical frame) with the mirrored target set's solvers, "
        "and answers the mean of the two (the mirror image taken back); a set whose mirror "
        "has no solver is solved once. The networks were trained mirrored too.",
    )
    completion_yaws: int = Field(
        default=1,
        ge=1,
        le=16,
        description="Key-point completion answers the mean of its networks' answers over "
        "this many turns of the key points about +Y (evenly spaced, each turned back): the "
        "networks were trained for any yaw, so the mean cancels what their answers owe to "
        "the facing. 1 = the key points as given.",
    )
    completion_mirror: bool = Field(
        default=False,
        description="Completion also averages over the mirror image of every view (left and "
        "right swapped, x -> -x; the networks were trained mirrored too).",
    )


#: Serving settings fixed by how the networks were trained and exported (the fused graphs
#: answer with them): nothing but a retrain changes them.
TRAINED_SERVING: frozenset[str] = frozenset({"body", "delta", "anchor"})


def serving_with(serving: Serving, overrides: Mapping[str, Any] | None) -> Serving:
    """``serving`` with ``overrides`` applied (an engine told to serve otherwise than its
    manifest says: by a bench, a test or the service's settings), validated as the
    manifest's block is. ``ValueError`` names a key that is not a setting, one fixed by
    training (:data:`TRAINED_SERVING`), or a value out of its range."""
    if not overrides:
        return serving
    unknown = sorted(set(overrides) - set(Serving.model_fields))
    if unknown:
        raise ValueError(f"not serving settings: {', '.join(unknown)}")
    fixed = sorted(set(overrides) & TRAINED_SERVING)
    if fixed:
        raise ValueError(f"fixed by how the networks were trained: {', '.join(fixed)}")
    return Serving.model_validate({**serving.model_dump(), **overrides})


class ModelEntry(_Strict):
    name: str
    kind: Literal["autoencoder", "solver", "completion", "fused", "mirror"]
    part: Literal["encoder", "decoder"] | None = None
    file: str
    sha256: str = Field(pattern=r"^[0-9a-f]{64}$")
    bytes: int = Field(gt=0)
    parameters: int = Field(gt=0)
    inputs: list[TensorSpec]
    outputs: list[TensorSpec]
    joints: list[str] = Field(default_factory=list)
    key: str | None = None
    level: int | None = None
    losses: dict[str, float] = Field(default_factory=dict)
    metrics: dict[str, float] = Field(default_factory=dict)

    @model_validator(mode="after")
    def _consistent(self) -> ModelEntry:
        unknown = [j for j in self.joints if j not in PARENT_NAMES]
        if unknown:
            raise ValueError(f"model {self.name}: unknown joints {unknown}")
        if self.kind == "autoencoder" and self.part is None:
            raise ValueError(f"model {self.name}: an autoencoder entry needs a part")
        if self.kind in ("solver", "fused", "mirror") and (
            not self.joints or self.key != set_key(self.joints)
        ):
            raise ValueError(f"model {self.name}: solver key must be the sorted joint set")
        if self.kind == "completion" and (self.level is None or not self.joints):
            raise ValueError(f"model {self.name}: a completion entry needs joints and a level")
        if Path(self.file).name != self.file:
            raise ValueError(f"model {self.name}: file must be a bare file name")
        return self


class Provenance(_Strict):
    data: list[dict[str, str]] = Field(
        description="Sources read (trainer.export.recorded_source): an archive's name and "
        'sha256 (`verified`: "false" where SHA256SUMS did not list it); an extracted '
        "folder's name, the sha256 of its files' list, `kind`, `files` and the `archive` "
        "SHA256SUMS names for it (not checked against it)."
    )
    dataset: dict[str, Any] = Field(default_factory=dict)
    split_seed: int
    config: dict[str, Any]
    git_commit: str
    versions: dict[str, str]
    training_seconds: dict[str, float] = Field(default_factory=dict)
    training_hosts: dict[str, list[str]] = Field(
        default_factory=dict,
        description="Per stage, the hosts that trained it (CPU model, SIMD level, torch, "
        "threads): the same seed on another CPU gives slightly other weights.",
    )
    serving_changes: list[dict[str, Any]] = Field(
        default_factory=list,
        description="Serving blocks set after the export without retraining (`pose-trainer "
        "serving`), oldest first: the version before, the settings changed (old and new "
        "value) and the git commit.",
    )


class Manifest(_Strict):
    schema_version: Literal[1] = 1
    version: str = Field(description="Model release identifier, served as `model`.")
    licence: str
    opset: int
    latent_dim: int = Field(gt=0)
    skeleton: SkeletonSpec
    normalisation: Normalisation
    serving: Serving = Serving()
    models: list[ModelEntry]
    provenance: Provenance
    content_sha256: str | None = Field(
        default=None,
        pattern=r"^[0-9a-f]{64}$",
        description="sha256 of the manifest as written (:func:`content_sha256`: every key "
        "but this one), set by `write_manifest`; a manifest whose content differs from it "
        "was edited by hand and is served under a version of its content "
        "(:func:`load_manifest`).",
    )
    #: the ``version`` the file holds, where :func:`load_manifest` serves another (a hand
    #: edit: :func:`served_version`); else None
    _written_version: str | None = PrivateAttr(default=None)

    @model_validator(mode="after")
    def _complete(self) -> Manifest:
        names = [m.name for m in self.models]
        if len(names) != len(set(names)):
            raise ValueError("model names must be unique")
        parts = {m.part for m in self.models if m.kind == "autoencoder"}
        if parts != {"encoder", "decoder"}:
            raise ValueError("the manifest needs one encoder and one decoder")
        keys = [m.key for m in self.models if m.kind == "solver"]
        if len(keys) != len(set(keys)):
            raise ValueError("solver target sets must be unique")
        fused = [m.key for m in self.models if m.kind == "fused"]
        if len(fused) != len(set(fused)) or not set(fused) <= set(keys):
            raise ValueError("fused graphs must be unique and each match a solver's set")
        if self.serving.delta and set(fused) != set(keys):
            raise ValueError("delta answers are served by fused graphs: one per solver set")
        mirrors = [m.key for m in self.models if m.kind == "mirror"]
        if len(mirrors) != len(set(mirrors)) or not all(
            k in fused and mirror_key(str(k)) in fused for k in mirrors
        ):
            raise ValueError(
                "mirror graphs must be unique and each match a fused graph whose mirror "
                "set has one too"
            )
        levels = sorted(m.level for m in self.models if m.kind == "completion" and m.level)
        if levels and levels != list(range(1, len(levels) + 1)):
            raise ValueError("completion levels must be 1..n")
        if self.serving.turn_critic == "completion" and not levels:
            raise ValueError("serving.turn_critic = completion needs completion level 1")
        for m in self.models if self.serving.completion_mirror else ():
            mirrored = {JOINT_NAMES[MIRROR[JOINT_INDEX[j]]] for j in m.joints or ()}
            if m.kind == "completion" and mirrored != set(m.joints or ()):
                raise ValueError(
                    f"serving.completion_mirror: completion level {m.level}'s key points "
                    "are not their own mirror image"
                )
        return self

    # -- convenience views -------------------------------------------------------------
    def autoencoder(self, part: Literal["encoder", "decoder"]) -> ModelEntry:
        return next(m for m in self.models if m.kind == "autoencoder" and m.part == part)

    def solvers(self) -> dict[str, ModelEntry]:
        return {str(m.key): m for m in self.models if m.kind == "solver"}

    def fused(self) -> dict[str, ModelEntry]:
        """Pre-fused single-solver graphs (``pose, targets -> pose``: encoder, solver,
        decoder and, with ``serving.delta``, the delta answer in one graph)."""
        return {str(m.key): m for m in self.models if m.kind == "fused"}

    def mirrors(self) -> dict[str, ModelEntry]:
        """Mirror graphs: a single-solver edit and its mirror image, averaged, in one graph
        (``serving.solve_mirror``; ``service.networks.both_views``)."""
        return {str(m.key): m for m in self.models if m.kind == "mirror"}

    def completion_levels(self) -> list[ModelEntry]:
        return sorted(
            (m for m in self.models if m.kind == "completion"), key=lambda m: m.level or 0
        )


def load_manifest(models_dir: Path | str, *, verify: bool = True) -> Manifest:
    """Read and validate ``models_dir/manifest.json``; with ``verify``, check every file.

    Raises ``ManifestError`` naming the file and the reason (missing, not JSON, schema
    violation, size or sha256 mismatch).
    """
    models_dir = Path(models_dir)
    path = models_dir / MANIFEST_NAME
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ManifestError(path, "missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ManifestError(path, f"not readable JSON ({exc})") from None
    try:
        manifest = Manifest.model_validate(raw)
    except ValidationError as exc:
        problems = "; ".join(
            f"{'.'.join(str(p) for p in e['loc']) or '<root>'}: {e['msg']}" for e in exc.errors()
        )
        raise ManifestError(path, f"invalid manifest ({problems})") from None
    if verify:
        for entry in manifest.models:
            verify_entry(models_dir, entry)
    served = served_version(raw, manifest)
    if served != manifest.version:  # edited by hand: served under its content's version
        written = manifest.version
        manifest = manifest.model_copy(update={"version": served})
        manifest._written_version = written
    return manifest


def verify_entry(models_dir: Path, entry: ModelEntry) -> None:
    """Check one model file's presence, size and sha256 against the manifest."""
    file = models_dir / entry.file
    if not file.is_file():
        raise ManifestError(file, "model file missing")
    size = file.stat().st_size
    if size != entry.bytes:
        raise ManifestError(file, f"size {size} bytes, manifest says {entry.bytes}")
    digest = sha256_file(file)
    if digest != entry.sha256:
        raise ManifestError(
            file, f"sha256 {digest[:12]}… does not match the manifest's {entry.sha256[:12]}…"
        )


def model_version(entries: Sequence[ModelEntry], serving: Serving) -> str:
    """The models' version: a hash of every file's sha256 and of the serving section as the
    manifest holds it (:func:`serving_json`: a setting added after it was written is left
    out), which changes answers as much as a file does (models exported before completion
    views hashed the files alone: :func:`edited_version` takes either)."""
    text = "".join(e.sha256 for e in entries) + serving.model_dump_json(exclude_unset=True)
    return "mx1-" + hashlib.sha256(text.encode()).hexdigest()[:12]


def content_sha256(raw: Mapping[str, Any]) -> str:
    """sha256 of a manifest's content as its file holds it (the parsed JSON ``raw``), every
    key but ``content_sha256`` itself, as canonical JSON (sorted keys, no spaces): what
    :func:`write_manifest` records and :func:`load_manifest` compares."""
    body = {k: v for k, v in raw.items() if k != "content_sha256"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def served_version(raw: Mapping[str, Any], manifest: Manifest) -> str:
    """The version ``manifest`` (parsed from ``raw``) is served under: its own ``version``
    where its content is as written, else one of its content (an audit, 2026-12-07: a
    hand-edited skeleton, joint order or ``serving.passes`` served other answers under the
    old ``model``). A manifest that records its content's sha256 (``content_sha256``,
    written by :func:`write_manifest`) is edited when any key differs: then
    ``"mx1-" + sha256(version + content sha256)[:12]``. An older one (no such key) is
    edited when its ``version`` is neither :func:`model_version` of its files and serving
    block nor its files' alone (the older hash): then :func:`model_version`."""
    recorded = raw.get("content_sha256")
    if recorded is not None:
        digest = content_sha256(raw)
        if digest == recorded:
            return manifest.version
        return "mx1-" + hashlib.sha256(f"{manifest.version} {digest}".encode()).hexdigest()[:12]
    now = model_version(manifest.models, manifest.serving)
    files = "mx1-" + hashlib.sha256("".join(e.sha256 for e in manifest.models).encode()).hexdigest()
    return manifest.version if manifest.version in (now, files[:16]) else now


def written_version(manifest: Manifest) -> str | None:
    """The version ``manifest``'s file holds where :func:`load_manifest` serves it under
    another (edited by hand: :func:`served_version`); else None."""
    return manifest._written_version


def edited_version(manifest: Manifest) -> str | None:
    """The version a hand-edited ``manifest`` is served under (:func:`served_version`,
    which :func:`load_manifest` made its ``version``), else None: its answers are no longer
    the ones its written version names. ``pose-trainer serving`` sets the serving block
    with a new version and content sha256."""
    return manifest.version if manifest._written_version is not None else None


def serving_json(serving: Serving) -> dict[str, Any]:
    """The serving block as a manifest file holds it: the settings it was written with. A
    setting added to :class:`Serving` after a file was written is absent from it, and its
    default is how those models were served before it existed, so re-writing an older
    manifest (a mirror pass, the version hash) keeps what it says and its version."""
    return serving.model_dump(mode="json", exclude_unset=True)


def manifest_json(manifest: Manifest) -> dict[str, Any]:
    """The manifest as its file holds it (:func:`serving_json` for the serving block)."""
    return {**manifest.model_dump(mode="json"), "serving": serving_json(manifest.serving)}


def stamped(manifest: Manifest) -> Manifest:
    """``manifest`` with its content's sha256 (``content_sha256``: :func:`content_sha256`
    of :func:`manifest_json` as a reader parses it): what :func:`write_manifest` writes."""
    body = {k: v for k, v in manifest_json(manifest).items() if k != "content_sha256"}
    digest = content_sha256(json.loads(json.dumps(body)))
    return manifest.model_copy(update={"content_sha256": digest})


def write_manifest(models_dir: Path, manifest: Manifest) -> Path:
    """Write ``manifest`` (:func:`stamped`: with its content's sha256, so that a hand edit
    is told at load) as ``models_dir/manifest.json``."""
    path = Path(models_dir) / MANIFEST_NAME
    text = json.dumps(manifest_json(stamped(manifest)), indent=2) + "\n"
    write_atomic(path, text.encode("utf-8"))
    return path
