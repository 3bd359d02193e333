"""The library calls a notebook makes (README, "Library use"): ``doorbatch.build_map`` then ``doorbatch.localize``
on what it returned, as ``doorbatch map`` then ``doorbatch localize --map`` would run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import doorbatch
from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, LocalizeConfig
from doorbatch.pipeline.localize.run import load_localization_map, localization_map_of
from doorbatch.pipeline.mapping import DoorMap
from tests.conftest import REPO

SAMPLE_LOGS = REPO / "datasets" / "sample" / "logs"
PASSES = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[DoorMap, Path]:
    """build_map's result on the sample's passes (paths as strings) and the grid map directory the CLI writes."""
    out = tmp_path_factory.mktemp("map") / "map"
    assert main(["map", *PASSES, "-o", str(out), "--stages", "grid", "-q"]) == 0
    return doorbatch.build_map(PASSES), out


def test_a_built_map_localizes_as_the_map_directory_written_of_it(built: tuple[DoorMap, Path]) -> None:
    door_map, map_dir = built
    written = load_localization_map(map_dir, LocalizeConfig())
    in_memory = localization_map_of(door_map, LocalizeConfig())
    assert np.array_equal(in_memory.occupancy.occupancy, written.occupancy.occupancy)
    assert (in_memory.occupancy.origin_x_m, in_memory.occupancy.origin_y_m) == (written.occupancy.origin_x_m,
                                                                                 written.occupancy.origin_y_m)
    assert len(written.doors) >= 5
    for name in ("hinge", "length", "closed_yaw", "angle_min", "angle_max", "door_id"):
        assert np.array_equal(getattr(in_memory.doors, name), getattr(written.doors, name)), name
    assert in_memory.pose_source == written.pose_source == "reference"
    assert np.array_equal(in_memory.field.dist, written.field.dist)


def test_localize_takes_the_built_map_its_directory_or_a_loaded_map_alike(built: tuple[DoorMap, Path]) -> None:
    door_map, map_dir = built
    config = DoorbatchConfig.model_validate({"localize": {"min_particles": 200, "max_particles": 300}})
    log = SAMPLE_LOGS / "loc_partial.mcap"
    from_memory = doorbatch.localize(str(log), door_map, config)
    from_dir = doorbatch.localize(log, str(map_dir), config)
    loaded = doorbatch.localize(log, load_localization_map(map_dir, config.localize), config)
    for other in (from_dir, loaded):
        assert np.array_equal(from_memory.pose, other.pose)
        assert np.array_equal(from_memory.door_mean, other.door_mean, equal_nan=True)
    assert from_memory.method == "rbpf" and len(from_memory.stamps_ns) > 100
    assert np.isfinite(from_memory.door_mean).any()


def test_build_map_takes_one_log_as_a_path_or_a_list() -> None:
    one = doorbatch.build_map(PASSES[0])
    listed = doorbatch.build_map([Path(PASSES[0])])
    assert len(one.passes) == len(listed.passes) == 1
    assert np.array_equal(one.static_map.occupancy, listed.static_map.occupancy)


def test_the_library_calls_are_named_on_the_package() -> None:
    assert set(doorbatch.__all__) >= {"build_map", "localize", "load_config"}
    assert doorbatch.load_config().localize.max_particles == DoorbatchConfig().localize.max_particles
    with pytest.raises(AttributeError):
        _ = doorbatch.no_such_call
