"""Route dependencies: the app's state, and the engine once the models are ready."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from fastapi import Depends, Request

from service.engine import Engine
from service.limits import Budget
from service.metrics import Metrics
from service.repository import ModelRepository
from service.settings import Settings


@dataclass
class ServiceState:
    """What one app instance holds (``app.state.pose``)."""

    settings: Settings
    repository: ModelRepository
    metrics: Metrics


async def get_state(request: Request) -> ServiceState:
    state: ServiceState = request.app.state.pose
    return state


State = Annotated[ServiceState, Depends(get_state)]


async def ready_engine(state: State) -> Engine:
    """The engine, or a 503 problem saying why the models are not ready."""
    return state.repository.ready_engine()


async def get_budget(request: Request, state: State) -> Budget:
    return Budget(request, state.settings.deadline_seconds)


ReadyEngine = Annotated[Engine, Depends(ready_engine)]
RequestBudget = Annotated[Budget, Depends(get_budget)]
