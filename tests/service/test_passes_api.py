"""``options.passes`` over HTTP (per request neural passes), on real poses and real BVH
characters: absent means the models' default (``GET /v1/models`` says which); an explicit
count answers bit for bit what an engine built with that many passes answers, in the pose
form, in a batch mixing counts (item list) and in the columnar form; the character and BVH
routes take it; a bad count is a 422 naming ``options.passes``; batches are priced by it."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from core.skeleton import JOINT_INDEX
from service import limits
from service.engine import Engine
from service.problems import SolveProblem
from tests.character_files import FILES
from tests.conftest import PosePairs
from tests.service.test_api import as_array, assert_problem, engine_pose, solve_body
from tests.service.test_characters import _goal
from tests.service.test_columnar import assert_same, columns, items
from tests.service.test_solve_forms import character_body

WRISTS = ["left_wrist", "right_wrist"]


@pytest.fixture(scope="module")
def by_passes(models_dir: Path) -> dict[int, Engine]:
    return {p: Engine(models_dir, serving={"passes": p}) for p in (1, 3)}


def test_models_say_their_default(client: Any, engine: Engine) -> None:
    r = client.get("/v1/models")
    assert r.status_code == 200
    assert r.json()["passes"] == engine.manifest.serving.passes == engine.serving.passes
    assert r.json()["retry_reach"] == engine.manifest.serving.retry_reach == 0.005


def test_pose_form_passes_equal_an_engine_built_with_them(
    client: Any, engine: Engine, by_passes: dict[int, Engine], real_poses: PosePairs
) -> None:
    for k in range(6):
        body = solve_body(real_poses, k, WRISTS)
        default = client.post("/v1/solve", json=body).json()
        explicit = client.post(
            "/v1/solve", json={**body, "options": {"passes": engine.serving.passes}}
        )
        assert explicit.json() == default  # absent = the models' default
        assert np.array_equal(as_array(default["pose"]), engine_pose(engine, body))
        for p, other in by_passes.items():
            out = client.post("/v1/solve", json={**body, "options": {"passes": p}})
            assert out.status_code == 200, out.text
            assert np.array_equal(as_array(out.json()["pose"]), engine_pose(other, body)), p
        # the count reaches the engine: a third pass moves every answer (one pass may not:
        # an answer it leaves more than serving.retry_reach short is retried, and then gets
        # what a second pass gives, the default's; 5 of these 6 with the models of
        # docs/generalisation-3.md item 50)
        three = client.post("/v1/solve", json={**body, "options": {"passes": 3}}).json()
        assert three["pose"] != default["pose"]


def test_batch_mixes_passes_item_by_item(client: Any, real_poses: PosePairs) -> None:
    bodies = [
        solve_body(real_poses, k, WRISTS if k % 2 else ["head", "left_ankle"], passes=1 + k % 4)
        for k in range(12)
    ]
    bodies[3]["options"] = {"passes": 2, "reach": "exact"}
    bodies[5]["options"] = {"passes": 4, "method": "fabrik"}  # FABRIK ignores it
    batch = client.post("/v1/solve/batch", json={"items": bodies})
    assert batch.status_code == 200, batch.text
    for b, got in zip(bodies, batch.json()["items"], strict=True):
        single = client.post("/v1/solve", json=b).json()
        assert got == single
    fab = {**bodies[5], "options": {"method": "fabrik"}}
    assert client.post("/v1/solve", json=fab).json() == batch.json()["items"][5]


@pytest.mark.parametrize("passes", [1, 3])
def test_columnar_passes_apply_to_every_item(
    client: Any, real_poses: PosePairs, passes: int
) -> None:
    body = columns(real_poses, 40, passes=passes)
    col = client.post("/v1/solve/batch", json=body)
    assert col.status_code == 200, col.text
    listed = client.post("/v1/solve/batch", json={"items": items(body)})
    assert_same(col.json(), listed.json()["items"])
    default = client.post("/v1/solve/batch", json=columns(real_poses, 40)).json()
    assert default["poses"] != col.json()["poses"]


def test_character_and_bvh_routes_take_passes(client: Any, bvh_files: dict[str, Path]) -> None:
    name = "reactidle-6ch"
    body = character_body(bvh_files[name], name, reach="soft")
    answers = {}
    for passes in (None, 1, 2):
        b = body if passes is None else {**body, "options": {"reach": "soft", "passes": passes}}
        for route in ("/v1/solve", "/v1/character/solve"):
            r = client.post(route, json=b)
            assert r.status_code == 200, r.text
            answers[passes, route] = r.json()
        assert answers[passes, "/v1/solve"] == answers[passes, "/v1/character/solve"]
    assert answers[None, "/v1/solve"] == answers[2, "/v1/solve"]  # the models' default
    assert answers[1, "/v1/solve"]["rotations"] != answers[2, "/v1/solve"]["rotations"]
    bad = {**body, "options": {"passes": 7}}
    assert_problem(client.post("/v1/solve", json=bad), 422, "options.passes")

    _, _, units, frame = FILES[name]
    text = bvh_files[name].read_text()
    wrist, goal, _ = _goal(text, frame)
    bvh: dict[str, Any] = {"bvh": text, "frame": frame,
                           "targets": [{"joint": wrist, "position": goal.tolist()}]}  # fmt: skip
    if units is not None:
        bvh["units"] = units
    one = client.post("/v1/bvh/solve", json={**bvh, "options": {"passes": 1}})
    two = client.post("/v1/bvh/solve", json={**bvh, "options": {"passes": 2}})
    assert one.status_code == two.status_code == 200, (one.text, two.text)
    assert one.json()["bvh"] != two.json()["bvh"]
    assert two.json() == client.post("/v1/bvh/solve", json=bvh).json()
    bad_bvh = {**bvh, "options": {"passes": 0}}
    assert_problem(client.post("/v1/bvh/solve", json=bad_bvh), 422, "options.passes")


def assert_bad_option(client: Any, real_poses: PosePairs, name: str, value: object) -> None:
    """``options.<name> = value`` is a 422 naming the field in the pose form, the item
    list (with the item's index) and the columnar form."""
    body = solve_body(real_poses, 0, WRISTS)
    bad = {**body, "options": {name: value}}
    assert_problem(client.post("/v1/solve", json=bad), 422, f"options.{name}")
    batch = {"items": [body, bad]}
    assert_problem(client.post("/v1/solve/batch", json=batch), 422, f"items[1].options.{name}")
    col = columns(real_poses, 3)
    col["options"] = {name: value}
    assert_problem(client.post("/v1/solve/batch", json=col), 422, f"options.{name}")


@pytest.mark.parametrize("value", [0, 5, -1, 1.5, 4.0000001, 5.0, "2", True, [2]])
def test_bad_passes_are_422_naming_the_field(
    client: Any, real_poses: PosePairs, value: object
) -> None:
    assert_bad_option(client, real_poses, "passes", value)


def test_prices_count_passes(real_poses: PosePairs) -> None:
    pose = real_poses.poses[real_poses.starts[0]]
    idx = np.asarray([JOINT_INDEX[j] for j in WRISTS], dtype=np.intp)
    soft = SolveProblem(pose=pose, target_idx=idx, target_pos=pose[idx],
                        weights=np.ones(2), n_targets=2)  # fmt: skip
    exact = dataclasses.replace(soft, reach="exact")
    fabrik = dataclasses.replace(soft, method="fabrik")
    one, two = limits.Pricing(1), limits.Pricing(2)
    assert limits.price(soft, one) == 1 and limits.price(exact, one) == limits.FABRIK_PRICE
    assert limits.price(soft, two) == 2 and limits.price(exact, two) == limits.FABRIK_PRICE + 1
    assert limits.price(dataclasses.replace(soft, passes=4), two) == 4
    assert limits.price(dataclasses.replace(fabrik, passes=4), two) == limits.FABRIK_PRICE
    many = [dataclasses.replace(soft, passes=4)] * limits.CHUNK_PRICE
    assert len(limits.chunks(many, one)) == 4  # four-pass items: a quarter as many per chunk
    assert len(limits.chunks([soft] * limits.CHUNK_PRICE, one)) == 1
    # an engine that retries a soft answer left short (serving.retry_reach) prices the
    # pass it may add on soft items, pinned or not; exact reach and FABRIK never retry
    retry = limits.Pricing(2, retry=True)
    pinned = dataclasses.replace(soft, n_targets=1)
    assert limits.price(soft, retry) == 3 and limits.price(exact, retry) == limits.price(exact, two)
    assert limits.price(pinned, retry) == limits.price(pinned, two) + 1
    assert limits.price(fabrik, retry) == limits.FABRIK_PRICE
    # (the costliest item asks for its mirror image too: twice its passes and retry)
    assert limits.max_item_price(retry) == limits.max_item_price(two) + 2
    # an engine that also solves the mirror image prices every neural unit twice, unless
    # the item says no (options.mirror); the FABRIK polish and FABRIK items are not doubled
    both = limits.Pricing(2, retry=True, mirror=True)
    assert limits.price(soft, both) == 2 * 3
    assert limits.price(dataclasses.replace(soft, mirror=False), both) == 3
    assert limits.price(dataclasses.replace(soft, mirror=True), retry) == 2 * 3
    assert limits.price(exact, both) == limits.price(exact, two) + 2
    assert limits.price(fabrik, both) == limits.FABRIK_PRICE
    assert limits.max_item_price(both) == limits.max_item_price(retry)


def test_engine_pricing_follows_the_models(engine: Engine, models_dir: Path) -> None:
    """``Pricing.of``: the engine's default passes, turn search, retry and mirror image, as
    it runs them."""
    pricing = limits.Pricing.of(engine)
    assert pricing == limits.Pricing(engine.serving.passes, engine.turn_search, True, True)
    assert engine.serving.retry_reach > 0  # the shipped models retry (serving.retry_reach)
    assert engine.serving.solve_mirror  # ... and solve the mirror image (serving.solve_mirror)
    assert not limits.Pricing.of(Engine(models_dir, serving={"retry_reach": 0.0})).retry
    # the polish of a short soft answer is not priced (service.limits says why)
    assert engine.serving.retry_polish
    assert limits.Pricing.of(Engine(models_dir, serving={"retry_polish": False})) == pricing
    assert not limits.Pricing.of(Engine(models_dir, serving={"solve_mirror": False})).mirror
