"""AMCL parameter files given as --config (Nav2's, ROS 1 amcl's YAML and launch files): each parameter lands on the
doorbatch key that does the same, and what a file leaves out takes that AMCL's own default."""

from __future__ import annotations

import json
import logging
import math
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
    assert lc.recovery_average_per_particle  # pf_update_sensor's w_avg /= sample_count
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
    ("odom_model_type: ackermann\nodom_alpha1: 0.2\n", "odom_model_type"),
    ("a:\n  amcl:\n    kld_err: 0.01\nb:\n  amcl:\n    kld_err: 0.02\n", "more than one"),
    ("amcl:\n  kld_err: 0.01\n  initial_pose_x: left\n", "initial_pose"),
    # rclcpp refuses a value whose type is not the declared one: nav2_amcl does not start
    ("amcl:\n  ros__parameters:\n    z_hit: true\n", "z_hit: True is not a float"),
    ("amcl:\n  ros__parameters:\n    alpha1: '0.3'\n", "alpha1: '0.3' is not a float"),
    ("amcl:\n  ros__parameters:\n    max_beams: '45'\n", "max_beams: '45' is not a int"),
    ("amcl:\n  ros__parameters:\n    max_beams: 45.5\n", "max_beams: 45.5 is not a int"),
    ("amcl:\n  ros__parameters:\n    do_beamskip: 1\n", "do_beamskip: 1 is not a bool"),
    ("amcl:\n  ros__parameters:\n    robot_model_type: 3\n", "robot_model_type: 3 is not a str"),
])
def test_what_cannot_be_translated_is_a_config_error(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        _load(tmp_path, text)


def test_an_integer_for_a_double_is_taken_as_that_double_with_a_note(tmp_path: Path,
                                                                    caplog: pytest.LogCaptureFixture) -> None:
    """rclcpp would refuse alpha1: 1 (declared a double); the replay takes it as 1.0 and says how to write it."""
    with caplog.at_level(logging.WARNING):
        lc = _load(tmp_path, "amcl:\n  ros__parameters:\n    alpha1: 1\n    max_particles: 2500.0\n").localize
    assert lc.alpha1 == 1.0 and lc.max_particles == 2500
    assert "write 1.0" in caplog.text


def test_a_parameter_file_weighs_each_particle_at_its_pose_and_starts_global_with_max_particles(
        tmp_path: Path) -> None:
    """AMCL has no region-averaged (smoothed, tempered) weighting, and pf_init_model draws max_samples."""
    assert DoorbatchConfig().localize.global_smoothing  # doorbatch's own default smooths
    for text in (NAV2_PARAMS, "amcl:\n  ros__parameters:\n    max_particles: 3000\n",
                 "odom_model_type: diff\nmax_particles: 4000\n"):
        lc = _load(tmp_path, text).localize
        assert not lc.global_smoothing
        assert lc.global_particles == lc.max_particles != DoorbatchConfig().localize.global_particles
        assert (lc.map_occupied_at_least, lc.map_free_at_most) == (100, 0)  # convertMap's obstacles and free cells


@pytest.mark.parametrize(("params", "expected"), [
    ({"laser_likelihood_max_dist": -1.0}, {"laser_likelihood_max_dist": 2.0}),
    ({"max_particles": -5}, {"max_particles": 2000}),
    ({"min_particles": -1}, {"min_particles": 500}),
    ({"resample_interval": 0}, {"resample_interval": 1}),
    ({"min_particles": 3000, "max_particles": 1000}, {"min_particles": 3000, "max_particles": 3000}),
    ({"min_particles": -1, "max_particles": 300}, {"min_particles": 500, "max_particles": 500}),
])
def test_values_nav2_amcl_replaces_at_start_are_replaced_with_its_warning(
        tmp_path: Path, caplog: pytest.LogCaptureFixture, params: dict[str, float], expected: dict[str, float]) -> None:
    """AmclNode::initParameters' semantic checks: the node warns and runs on; so does the replay."""
    text = "amcl:\n  ros__parameters:\n" + "".join(f"    {k}: {v}\n" for k, v in params.items())
    with caplog.at_level(logging.WARNING):
        lc = _load(tmp_path, text).localize
    assert {k: getattr(lc, k) for k in expected} == expected
    assert "nav2_amcl" in caplog.text and next(iter(params)) in caplog.text


# ROS 1 amcl (navigation's amcl_node.cpp, noetic) defaults, written out here from its source as the test's truth.
ROS1_DEFAULTS = {"alpha1": 0.2, "alpha2": 0.2, "alpha3": 0.2, "alpha4": 0.2, "alpha5": 0.2, "z_hit": 0.95,
                 "z_rand": 0.05, "sigma_hit": 0.2, "laser_likelihood_max_dist": 2.0, "laser_max_range": -1.0,
                 "laser_min_range": -1.0, "max_beams": 30, "min_particles": 100, "max_particles": 5000,
                 "pf_err": 0.01, "pf_z": 0.99, "recovery_alpha_slow": 0.001, "recovery_alpha_fast": 0.1,
                 "resample_interval": 2, "update_min_d": 0.2, "update_min_a": math.pi / 6}


def _indent(text: str, n: int) -> str:
    return "".join(" " * n + line + "\n" for line in text.splitlines())


@pytest.mark.parametrize("layout", ["flat", "rosparam dump", "namespaced dump"])
def test_a_ros1_amcl_file_takes_ros1_names_and_ros1_defaults(tmp_path: Path, layout: str) -> None:
    """A ``<rosparam>`` file loaded into the node (flat), or ``rosparam dump``'s nesting under the node's name."""
    params = "odom_alpha1: 0.1\nlaser_z_hit: 0.5\nkld_err: 0.05\nlaser_max_beams: 90\n"
    text = {"flat": params, "rosparam dump": "amcl:\n" + _indent(params, 2),
            "namespaced dump": "robot1:\n  amcl:\n" + _indent(params, 4)}[layout]
    lc = _load(tmp_path, text).localize
    expected = dict(ROS1_DEFAULTS, alpha1=0.1, z_hit=0.5, pf_err=0.05, max_beams=90)
    assert {k: getattr(lc, k) for k in expected} == pytest.approx(expected)
    # odom_model_type diff (the default): the alpha sums drawn as standard deviations; AMCL's likelihood_field
    assert lc.robot_model_type == "differential" and lc.alpha_sums_as_std
    assert lc.recovery_average_per_particle and not DoorbatchConfig().localize.recovery_average_per_particle
    assert lc.beam_combination == "amcl" and not lc.do_beamskip and lc.resample_neff_ratio == 1.0


@pytest.mark.parametrize(("model", "robot", "as_std", "swapped"), [
    ("diff", "differential", True, False), ("diff-corrected", "differential", False, False),
    ("omni", "omnidirectional", True, True), ("omni-corrected", "omnidirectional", False, True)])
def test_ros1_odometry_models(tmp_path: Path, model: str, robot: str, as_std: bool, swapped: bool) -> None:
    """ROS 1's omni models charge translation and strafe noise from rotation to alpha1 and rotation noise from
    rotation to alpha4 (amcl_odom.cpp); Nav2's omni model, doorbatch's, the other way round."""
    text = f"odom_model_type: {model}\nodom_alpha1: 0.1\nodom_alpha4: 0.4\nodom_alpha5: 0.05\n"
    lc = _load(tmp_path, text).localize
    assert (lc.robot_model_type, lc.alpha_sums_as_std) == (robot, as_std)
    assert (lc.alpha1, lc.alpha4) == ((0.4, 0.1) if swapped else (0.1, 0.4)) and lc.alpha5 == 0.05


def test_selective_resampling_and_the_start(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    text = ("odom_model_type: diff-corrected\nselective_resampling: true\ninitial_pose_x: 2.0\n"
            "initial_pose_a: 1.0\ninitial_cov_xx: 0.09\ninitial_cov_yy: 0.01\ninitial_cov_aa: 0.04\n"
            "gui_publish_rate: 10.0\nsome_new_knob: 1\nbeam_skip_error_threshold_: 0.5\n"
            "localize:\n  method: mcl\n")
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        lc = _load(tmp_path, text).localize
    # pf_update_resample: only when Neff < N/2, and then no random particles either
    assert lc.resample_neff_ratio == 0.5 and lc.neff_test_gates_recovery
    assert lc.init_sigma_xy_m == pytest.approx(math.sqrt(0.05))
    assert lc.init_sigma_yaw_deg == pytest.approx(math.degrees(0.2))
    assert lc.beam_skip_error_threshold == 0.5  # the name with the underscore, which amcl_node reads first
    assert lc.method == "mcl"  # a doorbatch section in the same file, not an unknown amcl parameter
    assert "--init 2,0,1" in caplog.text and "some_new_knob" in caplog.text and "gui_publish_rate" not in caplog.text
    assert "localize" not in caplog.text


def test_the_start_spread_takes_amcl_nodes_defaults(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    lc = _load(tmp_path, "odom_alpha1: 0.1\n").localize
    assert (lc.init_sigma_xy_m, lc.init_sigma_yaw_deg) == pytest.approx((0.5, 15.0))  # 0.5², (π/12)²
    assert not lc.neff_test_gates_recovery
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        lc = _load(tmp_path, "odom_alpha1: 0.1\ninitial_cov_aa: .nan\n").localize
    assert lc.init_sigma_yaw_deg == pytest.approx(15.0) and "NaN" in caplog.text
    with pytest.raises(ConfigError, match="initial_cov_xx must be positive"):
        _load(tmp_path, "odom_alpha1: 0.1\ninitial_cov_xx: -0.1\n")


def test_values_roscpp_would_not_read_leave_amcls_defaults(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """amcl_node reads its parameters with roscpp's typed param(): a bool from an int, or a number from a string,
    is rejected and the default runs; an int from a double is rounded."""
    text = "odom_alpha1: 0.1\ndo_beamskip: 1\nkld_err: '5e-2'\nlaser_max_beams: 60.4\n"
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        lc = _load(tmp_path, text + "laser_model_type: likelihood_field_prob\n").localize
    assert not lc.do_beamskip and lc.pf_err == 0.01 and lc.max_beams == 60
    assert "do_beamskip" in caplog.text and "kld_err" in caplog.text and "laser_max_beams" not in caplog.text


def test_a_rosparam_dump_of_a_running_node(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """``rosparam dump`` after dynamic_reconfigure started: its own defaults for what was not set are in the dump,
    with ``restore_defaults``; names Nav2 shares are enough under ``amcl``."""
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        lc = _load(tmp_path, "amcl:\n  min_particles: 300\n  recovery_alpha_slow: 0.0\n  restore_defaults: false\n"
                   ).localize
    assert lc.min_particles == 300 and lc.z_hit == 0.95 and lc.recovery_alpha_slow == 0.0
    assert "dynamic_reconfigure" in caplog.text


LAUNCH = """<launch>
  <arg name="scan_topic" default="base_scan"/>
  <arg name="use_omni" default="false"/>
  <arg name="x0" default="1.5"/>
  <node pkg="map_server" type="map_server" name="map_server" args="$(find my_robot)/maps/office.yaml"/>
  <param name="/robot1/amcl/laser_sigma_hit" value="0.15"/>
  <group ns="robot1">
    <arg name="x0" value="2.5"/>
    <node pkg="amcl" type="amcl" name="amcl">
      <remap from="scan" to="$(arg scan_topic)"/>
      <param name="odom_model_type" value="omni-corrected" if="$(arg use_omni)"/>
      <param name="odom_model_type" value="diff-corrected" unless="$(arg use_omni)"/>
      <param name="odom_alpha3" value="0.3"/>
      <param name="laser_max_beams" value="90" type="int"/>
      <param name="selective_resampling" value="1" type="bool"/>
      <param name="base_frame_id" value="base_footprint"/>
      <param name="use_map_topic" value="true"/>
      <param name="initial_pose_x" value="$(arg x0)"/>
      <param name="min_particles" value="$(eval 100 * 2)"/>
      <param name="do_beamskip" value="true" if="$(eval arg('use_omni'))"/>
      <rosparam>
        kld_err: 0.02
        laser_z_rand: 0.3
      </rosparam>
      <rosparam param="laser_likelihood_max_dist">1.5</rosparam>
      <rosparam ns="unused">
        kld_z: 0.5
      </rosparam>
      <rosparam file="$(find my_robot)/config/amcl_extra.yaml" command="load"/>
    </node>
    <group ns="amcl">
      <param name="update_min_d" value="0.05"/>
    </group>
  </group>
  <param name="robot1/amcl/max_particles" value="4000"/>
</launch>
"""


def _package(root: Path) -> None:
    """A catkin package my_robot with an amcl YAML, for $(find my_robot)."""
    (root / "src" / "my_robot" / "config").mkdir(parents=True)
    (root / "src" / "my_robot" / "package.xml").write_text("<package><name>my_robot</name></package>\n")
    (root / "src" / "my_robot" / "config" / "amcl_extra.yaml").write_text("odom_alpha4: 0.05\nkld_err: 0.03\n")


def test_a_ros1_launch_file_sets_the_node_as_roslaunch_would(tmp_path: Path, caplog: pytest.LogCaptureFixture,
                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "amcl.launch"
    path.write_text(LAUNCH)
    _package(tmp_path / "ws")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws" / "src"))
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        config = load_config(path)
    lc = config.localize
    assert lc.robot_model_type == "differential" and not lc.alpha_sums_as_std  # unless= chose diff-corrected
    assert (lc.alpha3, lc.max_beams, lc.z_rand) == (0.3, 90, 0.3)  # <param>, typed, <rosparam> text
    assert lc.neff_test_gates_recovery  # type="bool" value="1" is true
    assert (lc.alpha4, lc.pf_err) == (0.05, 0.03)  # the $(find) file, loaded after the text: it wins
    assert lc.laser_likelihood_max_dist == 1.5 and lc.pf_z == 0.99  # param= sets one name; ns= another node's
    # set outside the node, under its resolved name /robot1/amcl: from the top, and from a group ns="amcl"
    assert (lc.sigma_hit, lc.max_particles, lc.update_min_d) == (0.15, 4000, 0.05)
    assert lc.z_hit == 0.95  # ROS 1's default for what the file leaves out
    assert config.topics.scan == "/robot1/base_scan"  # the remap, in the node's namespace
    assert config.frames.base_link == "base_footprint"
    # what needs roslaunch itself is left out and said: min_particles ($(eval)), an if= with $(eval)
    assert lc.min_particles == 100 and not lc.do_beamskip
    assert "min_particles" in caplog.text and "do_beamskip" in caplog.text
    assert "--init 2.5,0,0" in caplog.text  # the group's own x0
    with_omni = tmp_path / "omni.launch"
    with_omni.write_text(LAUNCH.replace('name="use_omni" default="false"', 'name="use_omni" default="true"'))
    assert load_config(with_omni).localize.robot_model_type == "omnidirectional"


def test_a_launch_file_that_includes_the_amcl_launch_passes_its_args(tmp_path: Path, caplog: pytest.LogCaptureFixture,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    """A robot's navigation.launch including its package's amcl.launch (turtlebot3_navigation's layout): the included
    file is read under the include's ns, with the args passed overriding its defaults, the others its own."""
    launch = tmp_path / "ws" / "src" / "my_robot" / "launch"
    _package(tmp_path / "ws")
    launch.mkdir()
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws" / "src"))
    (launch / "amcl.launch").write_text("""<launch>
  <arg name="scan_topic" default="scan"/>
  <arg name="alpha" default="0.2"/>
  <arg name="z_hit" default="0.6"/>
  <arg name="x0" default="0.0"/>
  <node pkg="amcl" type="amcl" name="amcl">
    <remap from="scan" to="$(arg scan_topic)"/>
    <param name="odom_alpha1" value="$(arg alpha)"/>
    <param name="laser_z_hit" value="$(arg z_hit)"/>
    <param name="initial_pose_x" value="$(arg x0)"/>
    <rosparam file="$(dirname)/../config/amcl_extra.yaml" command="load"/>
  </node>
</launch>
""")
    (launch / "navigation.launch").write_text("""<launch>
  <arg name="x0" default="3.0"/>
  <include file="$(find my_robot)/launch/amcl.launch" ns="tb3">
    <arg name="scan_topic" value="base_scan"/>
    <arg name="alpha" value="0.05"/>
  </include>
</launch>
""")
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        config = load_config(launch / "navigation.launch")
    lc = config.localize
    assert lc.alpha1 == 0.05 and lc.z_hit == 0.6  # passed, and the included file's own default
    assert (lc.alpha4, lc.pf_err) == (0.05, 0.03)  # $(dirname) is the included file's folder
    assert config.topics.scan == "/tb3/base_scan"  # the remap, in the include's namespace
    assert "--init 0,0,0" in caplog.text  # x0 was not passed: the includer's own x0 does not leak in
    # pass_all_args hands every arg of the includer over; a relative file name is the includer's folder's
    (launch / "all.launch").write_text('<launch><arg name="x0" default="3.0"/><arg name="z_hit" default="0.7"/>'
                                       '<include file="amcl.launch" pass_all_args="true"/></launch>')
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        config = load_config(launch / "all.launch")
    assert config.localize.z_hit == 0.7 and "--init 3,0,0" in caplog.text
    # a multi-robot file: the namespace from an arg, a remap made above the include (the node resolves it in its
    # own namespace), and a passed value only roslaunch can compute (said, not replaced by the file's default)
    (launch / "plain.launch").write_text('<launch><arg name="alpha"/><node pkg="amcl" type="amcl" name="amcl">'
                                         '<param name="odom_alpha1" value="$(arg alpha)"/></node></launch>')
    (launch / "robots.launch").write_text('<launch><arg name="robot" default="robot2"/>'
                                          '<remap from="scan" to="front_scan"/>'
                                          '<include file="plain.launch" ns="$(arg robot)">'
                                          '<arg name="alpha" value="$(eval 0.05 * 2)"/></include></launch>')
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        config = load_config(launch / "robots.launch")
    assert config.topics.scan == "/robot2/front_scan"
    assert config.localize.alpha1 == 0.2 and "odom_alpha1" in caplog.text  # ROS 1's default, and the warning
    # an include that cannot be found is said; includes that include each other are an error, not a hang
    (launch / "lost.launch").write_text('<launch><include file="nowhere.launch"/></launch>')
    with pytest.raises(ConfigError, match=r"nowhere\.launch, which could not be read"):
        load_config(launch / "lost.launch")
    (launch / "loop.launch").write_text('<launch><include file="$(dirname)/loop.launch"/></launch>')
    with pytest.raises(ConfigError, match="cycle"):
        load_config(launch / "loop.launch")


def test_the_shipped_ros1_launch_example_reads() -> None:
    config = load_config(REPO / "configs" / "amcl_ros1.example.launch")
    lc = config.localize
    assert (lc.alpha1, lc.alpha3, lc.alpha5, lc.z_hit, lc.max_particles) == (0.2, 0.2, 0.1, 0.5, 3000)
    assert lc.alpha_sums_as_std and lc.resample_interval == 1
    assert config.topics.scan is None  # scan remapped to scan: the log's own scan topic


@pytest.mark.parametrize(("text", "message"), [
    ("<launch><node pkg='amcl' type='amcl' name='a'/><node pkg='amcl' type='amcl' name='b'/></launch>", "keep one"),
    ("<launch><include file='$(find my_robot)/launch/amcl.launch'/></launch>", "includes"),
    ("<launch><node pkg='amcl' type='amcl' name='amcl'>", "not a valid launch file"),
    ("<launch><node type='amcl' name='amcl'><param name='kld_err' value='x' type='double'/></node></launch>",
     "kld_err"),
    ("<launch><node type='amcl' name='amcl'><param name='kld_err' value='1' type='float'/></node></launch>",
     "unknown type"),
    ("<launch><node type='amcl' name='amcl'><rosparam file='$(find nowhere_pkg)/amcl.yaml'/></node></launch>",
     "ROS_PACKAGE_PATH"),
    ("<launch><node type='amcl' name='amcl'><rosparam>[1, 2]</rosparam></node></launch>", "mapping"),
])
def test_launch_files_that_cannot_be_read_are_config_errors(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "bad.launch"
    path.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_config(path)


ARGS_LAUNCH = """<launch>
  <arg name="alpha" default="0.2"/>
  <arg name="scan_topic" default="scan"/>
  <arg name="map_frame" value="map"/>
  <arg name="x0"/>
  <node pkg="amcl" type="amcl" name="amcl">
    <remap from="scan" to="$(arg scan_topic)"/>
    <param name="odom_alpha1" value="$(arg alpha)"/>
    <param name="global_frame_id" value="$(arg map_frame)"/>
    <param name="initial_pose_x" value="$(arg x0)"/>
  </node>
</launch>
"""


def test_args_passed_as_on_roslaunchs_command_line_set_the_top_files(tmp_path: Path,
                                                                     caplog: pytest.LogCaptureFixture) -> None:
    """``roslaunch amcl.launch alpha:=0.05 x0:=1.5``: a passed arg replaces its default, and fills one declared
    without a value (left out, with a warning, when not passed)."""
    path = tmp_path / "amcl.launch"
    path.write_text(ARGS_LAUNCH)
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        plain = load_config(path)
    assert plain.localize.alpha1 == 0.2 and "left out, needs ROS: initial_pose_x" in caplog.text
    assert plain.topics.scan is None
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="doorbatch"):
        config = load_config(path, launch_args={"alpha": "0.05", "x0": "1.5", "scan_topic": "base_scan"})
    assert config.localize.alpha1 == 0.05 and config.topics.scan == "/base_scan"
    assert "left out" not in caplog.text and "--init 1.5,0,0" in caplog.text


@pytest.mark.parametrize(("args", "message"), [
    ({"alpah": "0.05"}, r"unused args alpah \(the file declares: alpha, map_frame, scan_topic, x0\)"),
    ({"map_frame": "world"}, "cannot pass arg map_frame: the file sets it with value="),
])
def test_args_roslaunch_would_refuse_are_config_errors(tmp_path: Path, args: dict[str, str], message: str) -> None:
    path = tmp_path / "amcl.launch"
    path.write_text(ARGS_LAUNCH)
    with pytest.raises(ConfigError, match=message):
        load_config(path, launch_args=args)


def test_passed_args_follow_roslaunchs_scopes(tmp_path: Path) -> None:
    """A value= inside a top-level group refuses a passed arg too; one switched off by unless= does not count;
    a wrapper that passes all its args to the file with the node uses the ones it does not declare itself."""
    node = ('<node pkg="amcl" type="amcl" name="amcl"><param name="odom_alpha1" value="$(arg a)"/></node>')
    grouped = tmp_path / "grouped.launch"
    grouped.write_text(f'<launch><group><arg name="a" value="0.3"/>{node}</group></launch>')
    with pytest.raises(ConfigError, match="cannot pass arg a"):
        load_config(grouped, launch_args={"a": "0.05"})
    switched = tmp_path / "switched.launch"
    switched.write_text(f'<launch><arg name="a" value="0.3" if="false"/><arg name="a" default="0.2" unless="false"/>'
                        f'{node}</launch>')
    assert load_config(switched, launch_args={"a": "0.05"}).localize.alpha1 == 0.05
    assert load_config(switched).localize.alpha1 == 0.2
    (tmp_path / "inner.launch").write_text(f'<launch><arg name="a" default="0.2"/>{node}</launch>')
    wrapper = tmp_path / "wrapper.launch"
    wrapper.write_text('<launch><include file="$(dirname)/inner.launch" pass_all_args="true"/></launch>')
    assert load_config(wrapper, launch_args={"a": "0.05"}).localize.alpha1 == 0.05
    with pytest.raises(ConfigError, match="unused args b"):
        load_config(wrapper, launch_args={"b": "1"})
    plain = tmp_path / "plain.launch"  # an include without pass_all_args gets nothing from the command line
    plain.write_text('<launch><include file="$(dirname)/inner.launch"/></launch>')
    with pytest.raises(ConfigError, match=r"unused args a \(the file declares: none\)"):
        load_config(plain, launch_args={"a": "0.05"})


def test_launch_args_without_a_launch_file_are_a_config_error(tmp_path: Path) -> None:
    path = tmp_path / "amcl.yaml"
    path.write_text("amcl:\n  ros__parameters:\n    alpha1: 0.1\n")
    with pytest.raises(ConfigError, match="launch args are for a ROS 1 launch file"):
        load_config(path, launch_args={"alpha": "0.1"})
    with pytest.raises(ConfigError, match="launch args are for a ROS 1 launch file"):
        load_config(None, launch_args={"alpha": "0.1"})


def test_the_cli_passes_launch_args_and_refuses_malformed_ones(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    from doorbatch.cli import main

    path = tmp_path / "amcl.launch"
    path.write_text(ARGS_LAUNCH)
    assert main(["config", "--json", "--config", str(path), "--launch-arg", "alpha:=0.07",
                 "--launch-arg", "x0:=0"]) == 0
    assert json.loads(capsys.readouterr().out)["localize"]["alpha1"] == 0.07
    for bad in ("alpha=0.07", "alpha:=", "alpha:=0.1:=0.2", ":=0.1"):  # roslaunch's form, one value
        assert main(["config", "--config", str(path), "--launch-arg", bad]) == 2
        assert "is not NAME:=VALUE" in capsys.readouterr().err
    assert main(["config", "--json", "--config", str(path), "--launch-arg", " alpha := 0.08 "]) == 0
    assert json.loads(capsys.readouterr().out)["localize"]["alpha1"] == 0.08
    code = main(["config", "--config", str(path), "--launch-arg", "beta:=1"])
    assert code != 0 and "unused args beta" in capsys.readouterr().err


def test_the_map_topic_is_where_a_map_log_is_read(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    """amcl's map_topic had been dropped as a live node's setting; with --map LOG it names the map's topic."""
    with caplog.at_level(logging.WARNING):
        lc = _load(tmp_path, "amcl:\n  ros__parameters:\n    map_topic: my_map\n").localize
    assert lc.map_topic == "/my_map" and "map_topic" not in caplog.text
