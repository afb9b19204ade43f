"""``GET /v1/skeleton`` and ``GET /v1/models``."""

from __future__ import annotations

from fastapi import APIRouter

from core.skeleton import FRAME, JOINT_NAMES, PARENT_NAMES
from service.deps import ReadyEngine, State
from service.routes import ROUTE_PROBLEMS
from service.schemas import ModelInfo, ModelsResponse, SkeletonResponse

router = APIRouter(tags=["info"], responses=ROUTE_PROBLEMS)
#: Where the served models' card is: theirs, not the project's (a studio's retrained models
#: pointed at the shipped ones' card).
MODEL_CARD = "README.md beside manifest.json in the models folder served (pose-trainer model-card)"


@router.get("/v1/skeleton", response_model=SkeletonResponse)
async def skeleton(state: State) -> SkeletonResponse:
    """Joint names, parents, reference bone lengths (m) and frame conventions
    (available as soon as the manifest parses, before the models are ready)."""
    spec = state.repository.skeleton_spec()
    return SkeletonResponse(
        joints=list(JOINT_NAMES),
        parents=dict(PARENT_NAMES),
        reference_bone_lengths=dict(spec.reference_bone_lengths),
        frame=dict(FRAME),
    )


@router.get("/v1/models", response_model=ModelsResponse)
async def models(engine: ReadyEngine, state: State) -> ModelsResponse:
    """The loaded models: version, licence, solver sets, completion levels, metrics; body limit."""
    m = engine.manifest
    return ModelsResponse(
        version=m.version,
        licence=m.licence,
        model_card=MODEL_CARD,
        solver_sets=sorted(m.solvers()),
        completion_levels=[list(e.joints) for e in m.completion_levels()],
        passes=engine.serving.passes,
        carry=engine.serving.carry,
        turn_yaws=engine.turn_search.yaws,
        turn_fit=engine.turn_search.fit,
        turn_quick=engine.turn_search.quick,
        turn_gate=engine.turn_search.gate,
        turn_min_targets=engine.turn_search.min_targets,
        turn_critic=engine.turn_search.critic,
        turn_plausibility=engine.turn_search.plausibility,
        retry_reach=engine.serving.retry_reach,
        retry_polish=engine.serving.retry_polish,
        keep_ends=engine.serving.keep_ends,
        keep_elbows=engine.serving.keep_elbows,
        keep_ease=engine.serving.keep_ease,
        bend_side=engine.serving.bend_side,
        keep_collar=engine.serving.keep_collar,
        keep_feet=engine.serving.keep_feet,
        critic_fabrik=engine.serving.critic_fabrik,
        keep_pairs=engine.serving.keep_pairs,
        keep_pelvis=engine.serving.keep_pelvis,
        pelvis_travel=engine.serving.pelvis_travel,
        reach_travel=engine.serving.reach_travel,
        solve_mirror=engine.serving.solve_mirror,
        max_body_bytes=state.settings.max_body_bytes,
        models=[
            ModelInfo(
                name=e.name,
                kind=e.kind,
                key=e.key,
                joints=list(e.joints),
                parameters=e.parameters,
                bytes=e.bytes,
                metrics=dict(e.metrics),
            )
            for e in m.models
        ],
    )
