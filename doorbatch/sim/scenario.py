"""Simulation scenarios (``configs/scenarios/*.yaml``): robot passes, door states, people, sensors, noise.

A scenario is validated by frozen pydantic models with ``extra="forbid"`` at every level, and is mostly
world-independent: passes drive a world's named routes, door states are presets (``closed``, ``open``,
``partial``, ``random``, ``mixed``, ``keep``) with per-door overrides by name (every shipped world names
its doors d01, d02, ...). Every number carries its unit in its name; angles are degrees in YAML.

Resolving ``--scenario``: a value that names an existing file is that file; otherwise a bare name NAME
is ``configs/scenarios/NAME.yaml`` under the repository's configs folder
(``Path(doorbatch.__file__).parents[1] / "configs"``), which exists in a source checkout and an editable
install. Without ``--scenario`` the scenario is ``default``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

import doorbatch
from doorbatch.errors import ConfigError
from doorbatch.sim.world import RGB, Point, RGBStd, explain_validation, read_yaml

DoorState = Literal["closed", "open", "partial", "random"]
DoorPreset = Literal["closed", "open", "partial", "random", "mixed", "keep"]
Positive = Annotated[float, Field(gt=0)]
Fraction = Annotated[float, Field(ge=0, le=1)]

DEFAULT_START_TIME_S = 1_700_000_000


def configs_dir() -> Path:
    """The repository's ``configs`` folder (next to the ``doorbatch`` package)."""
    return Path(doorbatch.__file__).resolve().parents[1] / "configs"


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


# --------------------------------------------------------------------------------------------- robot, passes


class RobotSpec(_Model):
    """Differential-drive robot bounds (see :mod:`doorbatch.sim.motion`)."""

    radius_m: Positive = 0.25
    max_speed_mps: Positive = 0.8
    max_accel_mps2: Positive = 0.5
    max_yaw_rate_dps: Positive = 60.0
    max_yaw_accel_dps2: Positive = 120.0
    corner_radius_m: float = Field(0.6, ge=0)
    max_fillet_turn_deg: float = Field(100.0, ge=0, le=179)
    # Clearance check: the robot's disc must keep this far from walls and leaves, sampled at this rate.
    collision_check: bool = True
    collision_check_rate_hz: Positive = 20.0


class DoorChangeSpec(_Model):
    """A door moving during a pass: from its current angle to the target, linearly over ``duration_s``,
    starting ``at_s`` after the pass begins."""

    door: str
    at_s: float = Field(ge=0)
    duration_s: float = Field(1.5, gt=0)
    to_state: DoorState | None = None
    to_angle_deg: float | None = Field(None, ge=0)

    @model_validator(mode="after")
    def _one_target(self) -> DoorChangeSpec:
        if (self.to_state is None) == (self.to_angle_deg is None):
            raise ValueError("give exactly one of to_state and to_angle_deg")
        return self


class PassSpec(_Model):
    """One pass: the robot waits ``dwell_s`` (doors swing to this pass's states during the first
    ``door_swing_s`` of it), then drives a route (or explicit waypoints), then stops."""

    name: str = ""
    route: str | None = None
    reverse: bool = False
    waypoints_m: list[Point] | None = None
    dwell_s: float = Field(2.0, ge=0)
    end_dwell_s: float = Field(0.5, ge=0)
    doors: DoorPreset = "keep"
    door_states: dict[str, DoorState] = {}
    door_angles_deg: dict[str, Annotated[float, Field(ge=0)]] = {}
    changes: list[DoorChangeSpec] = []

    @model_validator(mode="after")
    def _one_path(self) -> PassSpec:
        if (self.route is None) == (self.waypoints_m is None):
            raise ValueError("give exactly one of route and waypoints_m")
        return self


class PersonSpec(_Model):
    """A walking person: a disc of ``radius_m`` moving at ``speed_mps`` along a route or waypoints from
    ``start_s`` (seconds after the log starts). ``once``: disappears at the end; ``loop``: starts over;
    ``pingpong``: walks back and forth."""

    name: str = ""
    route: str | None = None
    reverse: bool = False
    waypoints_m: list[Point] | None = None
    speed_mps: Positive = 1.2
    radius_m: Positive = 0.2
    height_m: Positive = 1.7
    start_s: float = Field(0.0, ge=0)
    mode: Literal["once", "loop", "pingpong"] = "pingpong"
    color_mean_rgb: RGB = (60.0, 70.0, 110.0)
    color_std_rgb: RGBStd = (15.0, 15.0, 15.0)

    @model_validator(mode="after")
    def _one_path(self) -> PersonSpec:
        if (self.route is None) == (self.waypoints_m is None):
            raise ValueError("give exactly one of route and waypoints_m")
        return self


# --------------------------------------------------------------------------------------------- sensors


class MountSpec(_Model):
    """A sensor's pose on base_link."""

    x_m: float = 0.0
    y_m: float = 0.0
    z_m: float = 0.0
    yaw_deg: float = 0.0


class LaserSpec(_Model):
    """A planar laser scanner. Beams span ``fov_deg`` centred on the mount's x axis.

    Range model: r = r_true + N(0, sigma_m²); with ``dropout_prob`` a beam is NaN (no information); with
    ``spurious_prob`` it returns a uniform random short range (unmodelled clutter); r_true beyond
    ``max_range_m`` or no hit gives +inf; readings ≥ ``max_range_m`` after noise become +inf too.
    """

    enabled: bool = True
    topic: str = "/scan"
    frame_id: str = "laser"
    rate_hz: Positive = 15.0
    fov_deg: float = Field(270.0, gt=0, le=360)
    beams: int = Field(720, ge=2)
    range_min_m: float = Field(0.05, ge=0)
    max_range_m: Positive = 20.0
    sigma_m: float = Field(0.01, ge=0)
    dropout_prob: Fraction = 0.01
    spurious_prob: Fraction = 0.0
    mount: MountSpec = MountSpec(x_m=0.2, z_m=0.3)
    # Time from the first beam to the last: a rotating laser (an LDS or RPLidar at 5 Hz takes most of 0.2 s) sees
    # each beam from where the robot is at that beam's time, stamps the first beam and sets time_increment.
    # 0: every beam at the stamp (Gazebo's and Stage's lasers).
    sweep_s: float = Field(0.0, ge=0)


class OdometrySpec(_Model):
    """Wheel odometry: α1..α4 of the odometry motion model per step (variances, see
    :mod:`doorbatch.sim.motion`), a distance scale error and a yaw drift per metre."""

    enabled: bool = True
    topic: str = "/odom"
    frame_id: str = "odom"
    child_frame_id: str = "base_link"
    rate_hz: Positive = 50.0
    alpha1: float = Field(0.02, ge=0)
    alpha2: float = Field(0.005, ge=0)
    alpha3: float = Field(0.02, ge=0)
    alpha4: float = Field(0.001, ge=0)
    scale_error: float = Field(0.015, gt=-0.5, lt=0.5)
    yaw_drift_rad_per_m: float = 0.003
    start_at_origin: bool = True  # odom starts at (0, 0, 0), like a robot that just booted
    publish_tf: bool = True


class ColorsSpec(_Model):
    """Per-beam colors (PointCloud2 x, y, z, rgb aligned with each scan).

    color = clip(g_scan · g(x, y) · (μ_surface + N(0, σ_surface²)) + N(0, sigma_rgb²)), with a per-scan
    exposure gain g_scan ~ N(1, gain_sigma²) and lighting g(x, y) = 1 + A·sin(2π(x + y)/period + phase).
    """

    enabled: bool = True
    topic: str = "/scan_colors"
    sigma_rgb: float = Field(3.0, ge=0)
    gain_sigma: float = Field(0.03, ge=0)
    lighting_amplitude: float = Field(0.12, ge=0, lt=1)
    lighting_period_m: Positive = 7.0
    lighting_phase_deg: float = 0.0


class CameraSpec(_Model):
    """A pinhole camera looking forward, rendered by per-column ray casting (flat shading)."""

    enabled: bool = True
    image_topic: str = "/camera/image_raw"
    info_topic: str = "/camera/camera_info"
    frame_id: str = "camera_optical"
    rate_hz: Positive = 5.0
    width_px: int = Field(320, ge=8)
    height_px: int = Field(240, ge=8)
    hfov_deg: float = Field(70.0, gt=1, lt=170)
    mount: MountSpec = MountSpec(x_m=0.15, z_m=1.1)
    noise_sigma: float = Field(0.0, ge=0)  # per-pixel Gaussian noise, grey levels (off: keeps logs small)
    exposure_sigma: float = Field(0.04, ge=0)  # per-frame brightness gain noise (auto exposure)
    ambient: Fraction = 0.55  # shade = ambient + (1 − ambient)·|cos(incidence)|


class DetectionsSpec(_Model):
    """Ground-truth door and handle boxes with noise (vision_msgs/Detection2DArray)."""

    enabled: bool = True
    topic: str = "/detections"
    center_sigma_px: float = Field(2.0, ge=0)
    size_sigma_px: float = Field(3.0, ge=0)
    miss_prob: Fraction = 0.05
    false_positive_rate: float = Field(0.02, ge=0)  # expected false boxes per image
    min_visible_fraction: Fraction = 0.3  # of the leaf's in-image part that must be unoccluded
    score_min: Fraction = 0.6


class GroundTruthSpec(_Model):
    """The ground-truth pose (nav_msgs/Odometry in the map frame)."""

    enabled: bool = True
    topic: str = "/ground_truth"
    frame_id: str = "map"
    rate_hz: Positive = 50.0


class SensorsSpec(_Model):
    """Every sensor; each can be disabled."""

    laser: LaserSpec = LaserSpec()
    odometry: OdometrySpec = OdometrySpec()
    colors: ColorsSpec = ColorsSpec()
    camera: CameraSpec = CameraSpec()
    detections: DetectionsSpec = DetectionsSpec()
    ground_truth: GroundTruthSpec = GroundTruthSpec()


class ScenarioSpec(_Model):
    """A whole scenario file."""

    name: str
    description: str = ""
    start_time_s: int = Field(DEFAULT_START_TIME_S, ge=0)
    base_frame_id: str = "base_link"
    partial_fraction: float = Field(0.5, gt=0, lt=1)  # "partial" = this fraction of a door's maximum angle
    door_swing_s: float = Field(1.0, gt=0)  # time a door takes to move between passes
    fixed_doors: list[str] = []  # doors that keep the first pass's angle in every pass
    robot: RobotSpec = RobotSpec()
    passes: list[PassSpec] = Field(min_length=1)
    people: list[PersonSpec] = []
    sensors: SensorsSpec = SensorsSpec()


Scenario = ScenarioSpec


def parse_scenario(data: object, source: str = "scenario") -> Scenario:
    """Validate a scenario mapping.

    Raises:
        ConfigError: unknown key, wrong type or value, with the key path.
    """
    try:
        return ScenarioSpec.model_validate(data)
    except ValidationError as err:
        raise ConfigError(f"{source}: {explain_validation(err)}") from err


def resolve_scenario(scenario: str | Path | None) -> Path:
    """The scenario file for ``--scenario`` (see the module docstring).

    Raises:
        ConfigError: neither an existing file nor a shipped scenario name.
    """
    if scenario is None:
        scenario = "default"
    path = Path(scenario)
    if path.is_file():
        return path
    shipped = configs_dir() / "scenarios" / f"{scenario}.yaml"
    if isinstance(scenario, str) and "/" not in scenario and shipped.is_file():
        return shipped
    names = sorted(p.stem for p in (configs_dir() / "scenarios").glob("*.yaml"))
    raise ConfigError(f"scenario {str(scenario)!r} is neither a file nor a shipped scenario "
                      f"(shipped: {', '.join(names) or 'none found'})")


def load_scenario(scenario: str | Path | None) -> Scenario:
    """Resolve and read a scenario.

    Raises:
        ConfigError: not found, unreadable, bad YAML, or invalid.
    """
    path = resolve_scenario(scenario)
    return parse_scenario(read_yaml(path), str(path))
