"""The library calls a notebook makes (README, "Library use"): ``doorbatch.build_map`` then ``doorbatch.localize``
on what it returned, as ``doorbatch map`` then ``doorbatch localize --map`` would run."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

import doorbatch
from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, LocalizeConfig, config_of, start_of
from doorbatch.errors import ConfigError, OptionalDependencyError, UsageError
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
    assert repr(from_memory).startswith("LocalizationResult(log=") and len(repr(from_memory)) < 300
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


@pytest.mark.parametrize("init", [[1.2, 0.0, 0.5], np.array([1.2, 0.0, 0.5]), "1.2,0,0.5", (1, 0, 0.5)])
def test_a_start_pose_is_the_same_in_any_form(init: object) -> None:
    assert start_of(init) == (1.2 if not isinstance(init, tuple) else 1.0, 0.0, 0.5)


@pytest.mark.parametrize("init", ["Reference", (1.0, 2.0), [1.0, float("nan"), 0.0], np.zeros((3, 1)), None, "1,2",
                                  [True, False, True], ["1", "2", "3"], [10**400, 0, 0]])
def test_a_start_in_no_known_form_is_a_usage_error(init: object) -> None:
    with pytest.raises(UsageError, match="init"):
        start_of(init)


def test_an_off_map_start_as_a_list_is_refused_as_the_tuple_is(built: tuple[DoorMap, Path]) -> None:
    door_map, _ = built
    for init in ([500.0, 500.0, 0.0], (500.0, 500.0, 0.0)):
        with pytest.raises(UsageError, match="outside the map"):
            doorbatch.localize(SAMPLE_LOGS / "loc_open.mcap", door_map, init=init)


def test_a_config_may_be_a_mapping_of_sections_checked_as_a_file_is(tmp_path: Path) -> None:
    assert config_of({"localize": {"max_particles": 700}}).localize.max_particles == 700
    assert config_of(None) == DoorbatchConfig()
    with pytest.raises(ConfigError, match="max_particls"):
        config_of({"localize": {"max_particls": 700}})
    with pytest.raises(UsageError, match="LocalizeConfig"):
        config_of(LocalizeConfig())  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="no log given"):
        doorbatch.build_map([])
    path = tmp_path / "my.yaml"
    path.write_text("localize:\n  max_particles: 900\n")
    assert doorbatch.load_config(str(path), "seed=3").localize.max_particles == 900
    assert doorbatch.load_config(overrides="seed=3").seed == 3


def test_load_localization_map_takes_a_path_as_text_and_the_whole_config(built: tuple[DoorMap, Path]) -> None:
    _, map_dir = built
    whole = doorbatch.load_localization_map(str(map_dir), DoorbatchConfig())
    section = doorbatch.load_localization_map(map_dir, LocalizeConfig())
    assert np.array_equal(whole.field.dist, section.field.dist) and len(whole.doors) == len(section.doors)


def test_an_optional_dependency_error_crosses_a_process_boundary() -> None:
    raised = OptionalDependencyError("torch", "torch")
    raised.add_note("while localizing run.mcap")
    err = pickle.loads(pickle.dumps(raised))
    assert isinstance(err, OptionalDependencyError) and err.__notes__ == ["while localizing run.mcap"]
    assert str(err) == 'torch is not installed: pip install "doorbatch[torch]"'


def test_results_show_as_one_line(built: tuple[DoorMap, Path]) -> None:
    door_map, _ = built
    assert repr(door_map).startswith("DoorMap(pose_source='reference', passes=3, doors=") and len(repr(door_map)) < 200
