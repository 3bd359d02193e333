"""Nav2 AMCL parameter files given as --config: each parameter lands on the doorbatch key that does the same."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.errors import ConfigError
from tests.conftest import REPO

# nav2_bringup's nav2_params.yaml (Humble): its amcl node as the repository ships it, and two other nodes.
NAV2_PARAMS = (REPO / "configs" / "nav2_params.example.yaml").read_text() + """
bt_navigator:
  ros__parameters:
    global_frame: map
    robot_base_frame: base_link

controller_server:
  ros__parameters:
    controller_frequency: 20.0
"""


def _load(tmp_path: Path, text: str, *overrides: str) -> DoorbatchConfig:
    path = tmp_path / "nav2_params.yaml"
    path.write_text(text)
    return load_config(path, overrides)


def test_nav2_bringups_params_file_configures_localize_as_amcl_runs(tmp_path: Path) -> None:
    lc = _load(tmp_path, NAV2_PARAMS).localize
    assert (lc.alpha1, lc.alpha2, lc.alpha3, lc.alpha4, lc.alpha5) == (0.2, 0.2, 0.2, 0.2, 0.2)
    assert lc.robot_model_type == "differential"
    assert (lc.z_hit, lc.z_rand, lc.sigma_hit, lc.laser_likelihood_max_dist) == (0.5, 0.5, 0.2, 2.0)
    assert (lc.laser_max_range, lc.laser_min_range, lc.max_beams) == (100.0, -1.0, 60)
    assert (lc.min_particles, lc.max_particles, lc.pf_err, lc.pf_z) == (500, 2000, 0.05, 0.99)
    assert (lc.update_min_d, lc.update_min_a, lc.resample_interval) == (0.25, 0.2, 1)
    # likelihood_field: AMCL's 1 + sum(pz^3), no beam skipping, and resampling on every update
    assert lc.beam_combination == "amcl" and not lc.do_beamskip and lc.resample_neff_ratio == 1.0
    assert lc.beam_skip_support == "particles"  # if skipping is on (likelihood_field_prob): nav2's rule
    config = _load(tmp_path, NAV2_PARAMS)
    assert config.frames.base_link == "base_footprint" and config.topics.scan == "/scan"


def test_parameters_the_file_leaves_out_take_nav2s_defaults_not_doorbatchs(tmp_path: Path) -> None:
    lc = _load(tmp_path, "amcl:\n  ros__parameters:\n    alpha1: 0.01\n    max_particles: 800\n").localize
    assert lc.alpha1 == 0.01 and lc.max_particles == 800
    assert (lc.alpha2, lc.z_hit, lc.sigma_hit, lc.pf_err, lc.update_min_d) == (0.2, 0.5, 0.2, 0.05, 0.25)
    assert lc.beam_combination == "amcl" and not lc.do_beamskip
    assert DoorbatchConfig().localize.sigma_hit != lc.sigma_hit  # a real difference from doorbatch's defaults
    config = _load(tmp_path, "amcl:\n  ros__parameters:\n    alpha1: 0.01\n")
    assert config.frames == DoorbatchConfig().frames  # frames only where the file names them


def test_likelihood_field_prob_is_the_product_with_beam_skipping_as_given(tmp_path: Path) -> None:
    text = ("amcl:\n  ros__parameters:\n    laser_model_type: likelihood_field_prob\n    do_beamskip: true\n"
            "    beam_skip_distance: 0.3\n")
    lc = _load(tmp_path, text).localize
    assert lc.beam_combination == "product" and lc.do_beamskip and lc.beam_skip_distance == 0.3


def test_beam_skipping_asked_of_likelihood_field_is_ignored_as_nav2_does(tmp_path: Path,
                                                                         caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        lc = _load(tmp_path, "amcl:\n  ros__parameters:\n    do_beamskip: true\n").localize
    assert not lc.do_beamskip
    assert "likelihood_field_prob" in caplog.text


def test_the_omni_motion_model_and_alpha5(tmp_path: Path) -> None:
    text = "amcl:\n  ros__parameters:\n    robot_model_type: nav2_amcl::OmniMotionModel\n    alpha5: 0.05\n"
    lc = _load(tmp_path, text).localize
    assert lc.robot_model_type == "omnidirectional" and lc.alpha5 == 0.05
    old = _load(tmp_path, "amcl:\n  ros__parameters:\n    robot_model_type: omnidirectional\n").localize
    assert old.robot_model_type == "omnidirectional"


def test_a_namespaced_amcl_node_and_doorbatch_sections_in_the_same_file(tmp_path: Path) -> None:
    text = ("robot1:\n  amcl:\n    ros__parameters:\n      max_particles: 3000\n"
            "localize:\n  method: mcl\n  max_particles: 4000\n")
    lc = _load(tmp_path, text, "localize.min_particles=100").localize
    assert lc.method == "mcl" and lc.max_particles == 4000  # the file's own section wins over the translation
    assert lc.min_particles == 100 and lc.z_hit == 0.5  # --set over both; the rest from nav2


def test_the_initial_pose_is_named_as_the_init_to_pass(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    text = ("amcl:\n  ros__parameters:\n    set_initial_pose: true\n"
            "    initial_pose:\n      x: 1.5\n      y: -2.0\n      z: 0.0\n      yaw: 0.5\n    some_new_knob: 3\n")
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        _load(tmp_path, text)
    assert "--init 1.5,-2,0.5" in caplog.text
    assert "some_new_knob" in caplog.text and "initial_pose.z" not in caplog.text


@pytest.mark.parametrize(("text", "message"), [
    ("amcl:\n  ros__parameters:\n    laser_model_type: beam\n", "not implemented"),
    ("amcl:\n  ros__parameters:\n    laser_model_type: sonar\n", "likelihood_field_prob"),
    ("amcl:\n  ros__parameters:\n    robot_model_type: nav2_amcl::Ackermann\n", "robot_model_type"),
    ("bt_navigator:\n  ros__parameters:\n    global_frame: map\n", "without an 'amcl' node"),
    ("a:\n  amcl:\n    ros__parameters: {}\nb:\n  amcl:\n    ros__parameters: {}\n", "more than one"),
    ("amcl:\n  ros__parameters:\n    max_particles: many\n", "max_particles"),
    ("amcl:\n  ros__parameters:\n    set_initial_pose: true\n    initial_pose: {x: one}\n", "initial_pose"),
    ("odom_model_type: diff\nodom_alpha1: 0.2\nlaser_z_hit: 0.95\n", "ROS 1 amcl"),  # a ROS 1 launch's rosparams
    ("amcl:\n  kld_err: 0.01\n", "ROS 1 amcl"),
])
def test_what_cannot_be_translated_is_a_config_error(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _load(tmp_path, text)
