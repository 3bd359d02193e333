"""Config: defaults file equals the models, overrides are typed, unknown keys name the closest."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml
from pydantic import BaseModel

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.errors import ConfigError
from tests.conftest import REPO


def test_configs_default_yaml_equals_the_model_defaults() -> None:
    on_disk = yaml.safe_load((REPO / "configs" / "default.yaml").read_text())
    assert on_disk == DoorbatchConfig().as_dict()


def test_set_overrides_are_typed_and_merge(tmp_path: Path) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("laser:\n  beam_stride: 2\nio:\n  gap_factor: 7\n")
    config = load_config(cfg, ["laser.beam_stride=3", "topics.scan=/front_scan"])
    assert config.laser.beam_stride == 3
    assert config.io.gap_factor == 7.0
    assert config.topics.scan == "/front_scan"
    assert config.hash() != DoorbatchConfig().hash()
    assert load_config().hash() == DoorbatchConfig().hash()


@pytest.mark.parametrize(("override", "expected"), [
    ("laser.beam_strid=2", "laser.beam_stride"),
    ("framse.map=x", "frames"),
    ("seeed=3", "seed"),
])
def test_unknown_key_names_closest_valid(override: str, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected):
        load_config(overrides=[override])


def test_wrong_type_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match=r"laser\.beam_stride"):
        load_config(overrides=["laser.beam_stride=zero"])
    with pytest.raises(ConfigError, match=r"expected section\.key=value"):
        load_config(overrides=["laser.beam_stride"])


@pytest.mark.parametrize(("override", "named"), [
    ("seed=-1", "seed"),
    ("localize.seed=-2", "seed"),
    ("localize.min_particles=6000", "min_particles"),
    ("run.init=garbage", "init"),
    ("run.init=nan,0,0", "init"),
    ("run.methods=[mcl,mcl]", "methods"),
    ("run.map_stages=[grid,grid]", "map_stages"),
    ("run.map_stages=[slam]", "map_stages"),
])
def test_values_no_step_could_run_with_are_config_errors(override: str, named: str) -> None:
    """Caught when the config is read (exit 2), not by every step of a batch (exit 4) or as a crash."""
    with pytest.raises(ConfigError, match=named):
        load_config(overrides=[override])


def test_a_pose_and_a_topic_are_valid_run_inits() -> None:
    assert load_config(overrides=["run.init=1.5,-2,0.3"]).run.init == "1.5,-2,0.3"
    assert load_config(overrides=["run.init=/initialpose"]).run.init == "/initialpose"


def _float_keys() -> list[str]:
    """Every config key whose value is a number with a fraction (float, or float or None)."""
    keys = []
    for name, section in DoorbatchConfig.model_fields.items():
        model = section.annotation
        if not isinstance(model, type) or not issubclass(model, BaseModel):
            continue
        keys += [f"{name}.{key}" for key, info in model.model_fields.items()
                 if info.annotation in (float, float | None)]
    return keys


def test_no_config_number_takes_nan_or_infinity_unless_it_says_what_it_means() -> None:
    # a fuzzer's .inf or .nan reached int() or an array size: an internal error, or a hang (hAP)
    keys = _float_keys()
    assert len(keys) > 100
    allowed = {"doorpose.door_width_max_m"}  # inf: no upper width (config comment)
    for key in keys:
        for value in (".nan", ".inf", "-.inf"):
            if key in allowed:
                continue
            with pytest.raises(ConfigError, match="finite number"):
                load_config(overrides=[f"{key}={value}"])
    assert load_config(overrides=["doorpose.door_width_max_m=.inf"]).doorpose.door_width_max_m == float("inf")
