"""World files: validation, door geometry, walls cut where closed doors are flush with them."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sim_helpers import OFFICE, WORLDS

from doorbatch.errors import ConfigError
from doorbatch.sim.raycast import cast_rays
from doorbatch.sim.scenario import load_scenario
from doorbatch.sim.simulate import random_streams
from doorbatch.sim.timeline import plan_scenario
from doorbatch.sim.world import SurfaceKind, door_leaf_segments, load_world, parse_world, read_yaml

SHIPPED_WORLDS = sorted(WORLDS.glob("*.yaml"))
SHIPPED_SCENARIOS = ["default", "mapping_pass", "loc_closed", "loc_open", "loc_partial"]


def test_the_three_required_worlds_are_shipped() -> None:
    assert {p.stem for p in SHIPPED_WORLDS} >= {"office_corridor", "l_corridor", "double_door"}


@pytest.mark.parametrize("path", SHIPPED_WORLDS, ids=lambda p: p.stem)
def test_shipped_world_builds_with_doors_pillars_and_niches(path: object) -> None:
    world = load_world(path)  # type: ignore[arg-type]
    assert world.doors.count >= 8
    kinds = set(world.segment_kind.tolist())
    assert {int(SurfaceKind.WALL), int(SurfaceKind.ROOM)} <= kinds
    assert kinds & {int(SurfaceKind.PILLAR), int(SurfaceKind.NICHE)}, "corridor ends need measurable features"
    assert {"main", "tour", "walk_north", "walk_south"} <= set(world.routes)


@pytest.mark.parametrize("path", SHIPPED_WORLDS, ids=lambda p: p.stem)
@pytest.mark.parametrize("scenario", SHIPPED_SCENARIOS)
def test_every_shipped_scenario_plans_in_every_world_without_collisions(path: object, scenario: str) -> None:
    world = load_world(path)  # type: ignore[arg-type]
    plan = plan_scenario(world, load_scenario(scenario), random_streams(0)["scenario"])  # checks clearance
    assert 20.0 < plan.end_s < 200.0


def test_office_corridor_has_two_nearly_opposite_door_pairs() -> None:
    doors = load_world(OFFICE).doors
    closed = door_leaf_segments(doors, np.zeros(doors.count))
    centre_x = closed[:, :, 0].mean(axis=1)
    north = closed[:, 0, 1] > 0
    gaps = np.abs(centre_x[north][:, None] - centre_x[~north][None, :])
    assert (gaps < 1.0).sum() >= 2


def test_leaf_free_end_follows_closed_yaw_and_opening_sign() -> None:
    doors = load_world(OFFICE).doors
    i = doors.index("d01")  # hinge (3, 1.1), closed along +x, opens counter-clockwise
    leaf = door_leaf_segments(doors, np.full(doors.count, math.radians(90.0)))[i]
    np.testing.assert_allclose(leaf[0], [3.0, 1.1])
    np.testing.assert_allclose(leaf[1], [3.0, 2.0], atol=1e-12)
    j = doors.index("d02")  # hinge (5.6, -1.1), closed along +x, opens clockwise into the south room
    leaf = door_leaf_segments(doors, np.full(doors.count, math.radians(90.0)))[j]
    np.testing.assert_allclose(leaf[1], [5.6, -2.0], atol=1e-12)


def test_closed_door_is_flush_with_its_cut_wall() -> None:
    world = load_world(OFFICE)
    i = world.doors.index("d01")
    centre = np.array([3.45, 0.0])
    up = np.array([[0.0, 1.0]])
    # the static world has a gap there: the ray passes the wall line and reaches the room's back wall
    r_static, _ = cast_rays(centre, up, world.segments)
    assert r_static[0] == pytest.approx(4.6)
    closed = np.concatenate([world.segments, door_leaf_segments(world.doors, np.zeros(world.doors.count))])
    r_closed, idx = cast_rays(centre, up, closed)
    assert r_closed[0] == pytest.approx(1.1)
    assert idx[0] == world.segments.shape[0] + i
    # walls end exactly at the hinge and at the free end of the closed leaf
    ends = world.segments.reshape(-1, 2)
    assert np.min(np.hypot(*(ends - [3.0, 1.1]).T)) < 1e-9
    assert np.min(np.hypot(*(ends - [3.9, 1.1]).T)) < 1e-9


def test_unknown_world_key_is_a_config_error_with_its_path() -> None:
    data = read_yaml(OFFICE)
    assert isinstance(data, dict)
    data["doors"][0]["hinge_xy"] = [0, 0]
    with pytest.raises(ConfigError, match=r"doors\.0\.hinge_xy"):
        parse_world(data, "bad.yaml")


def test_undefined_material_is_a_config_error() -> None:
    data = read_yaml(OFFICE)
    assert isinstance(data, dict)
    data["doors"][0]["material"] = "marble"
    with pytest.raises(ConfigError, match="marble"):
        parse_world(data, "bad.yaml")
