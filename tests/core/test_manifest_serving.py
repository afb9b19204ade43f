"""Serving settings other than the manifest's (core.manifest.serving_with): the one place
an engine, a bench or a test asks for them, validated as the manifest's block is."""

from __future__ import annotations

from pathlib import Path

import pytest

from core.manifest import TRAINED_SERVING, Serving, load_manifest, serving_with
from service.engine import Engine


@pytest.fixture(scope="module")
def shipped(models_dir: Path) -> Serving:
    return load_manifest(models_dir, verify=False).serving


def test_overrides_change_only_what_they_name(shipped: Serving) -> None:
    assert serving_with(shipped, None) is shipped and serving_with(shipped, {}) is shipped
    other = serving_with(shipped, {"passes": shipped.passes + 1, "turn_critic": "autoencoder"})
    assert other.passes == shipped.passes + 1 and other.turn_critic == "autoencoder"
    assert other.model_dump(exclude={"passes", "turn_critic"}) == shipped.model_dump(
        exclude={"passes", "turn_critic"}
    )


@pytest.mark.parametrize(
    ("overrides", "names"),
    [
        ({"passes": 2, "pases": 3, "carry_all": 1}, "not serving settings: carry_all, pases"),
        ({"delta": not True, "body": "nearest_skeleton"}, "trained: body, delta"),
        ({"carry": 1.5}, "carry"),
        ({"passes": 0}, "passes"),
        ({"carry": float("nan")}, "carry\n  Input should be a finite number"),
        ({"keep_pelvis": float("inf")}, "keep_pelvis\n  Input should be a finite number"),
        ({"turn_critic": "critic"}, "turn_critic"),
    ],
)
def test_bad_overrides_are_refused_by_name(
    shipped: Serving, overrides: dict[str, object], names: str
) -> None:
    with pytest.raises(ValueError, match=names):
        serving_with(shipped, overrides)


def test_trained_settings_are_serving_fields() -> None:
    assert set(Serving.model_fields) >= TRAINED_SERVING


def test_an_engine_serves_its_overrides(models_dir: Path) -> None:
    engine = Engine(models_dir, serving={"passes": 1, "turn_yaws": 1, "keep_pelvis": 0.02})
    assert (engine.serving.passes, engine.turn_search.yaws, engine.serving.keep_pelvis) == (
        1,
        1,
        0.02,
    )
    assert engine.serving.carry == engine.manifest.serving.carry
    with pytest.raises(ValueError, match="anchor"):
        Engine(models_dir, serving={"anchor": False})
