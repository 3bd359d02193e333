"""Paper 003's experiments on simulated door scenes, as library functions (Tables I and II).

* Table I (:func:`compare_fits`): N scenes with obstacles near the door edges and noisy boxes, each seen
  from a random pose in front of the door; every fit estimates the door, and the error is
  |Δx| + |Δy| + |Δθ| of the centre and normal yaw against the truth. Handle sides are checked on every
  sample where the true handle box is visible.
* Table II (:func:`compare_goal_updating`): N start poses from which the door is estimable; from each, one
  run with ``initial`` and one with ``continuous`` goal updating (same scene, same seed).
* :func:`z_test_greater`: the one-sided two-sample z-test with known variances the paper ran
  (Montgomery & Runger): z = (x̄_b − x̄_a)/√(σ_a²/n_a + σ_b²/n_b), p = 1 − Φ(z), H1: μ_b > μ_a.

Results turn into rows of DESIGN's metrics.parquet with :func:`fit_comparison_metrics` and
:func:`goal_updating_metrics`; door poses of a run against their truth with :func:`door_pose_metrics` (pure:
``doorbatch evaluate`` writes them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt
from pydantic import BaseModel, ConfigDict, Field, ValidationError
from scipy import stats

from doorbatch.config import DoorbatchConfig, deep_merge, read_yaml_mapping
from doorbatch.errors import ConfigError, PipelineError
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.doorpose.approach import GoalUpdating, simulate_approach, summed_pose_error
from doorbatch.pipeline.doorpose.fusion import door_box, estimate_door, to_planar, usable_detections
from doorbatch.pipeline.doorpose.line_fit import LineFit
from doorbatch.pipeline.evaluate.report import MetricRow
from doorbatch.sim.door_scene import CAMERA_FRAME, PAPER_DETECTIONS, DoorSceneSpec, make_door_scene, observe
from doorbatch.sim.motion import OdometryNoise
from doorbatch.sim.scenario import OdometrySpec
from doorbatch.sim.world import explain_validation

FloatArray = npt.NDArray[np.float64]


class DoorPoseExperiment(BaseModel):
    """An experiment file (``configs/experiments/doorpose_*.yaml``): which table, how many samples, the
    seed, the robot's start region in front of the door, and config overrides (``config:``)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    experiment: Literal["doorpose_fit_comparison", "doorpose_goal_updating"]
    description: str = ""
    samples: int = Field(20, ge=2)
    seed: int = 0
    distance_m: tuple[float, float] = (1.5, 3.0)  # camera-side distance of the robot from the wall
    lateral_m: tuple[float, float] = (-0.6, 0.6)
    heading_deg: tuple[float, float] = (-15.0, 15.0)  # relative to facing the door
    obstacles_per_scene: tuple[int, int] = (1, 2)
    # Expected false door boxes per image (0: the paper's setting, see doorbatch.sim.door_scene).
    false_positive_rate: float = Field(0.0, ge=0.0)
    max_attempts_factor: int = Field(5, ge=1)  # draws per wanted sample before giving up
    config: dict[str, object] = {}


@dataclass(frozen=True)
class FitComparison:
    """Table I: per fit, the summed pose error of every sample (all fits see the same samples)."""

    errors: dict[str, FloatArray]
    handle_checked: int  # samples whose true handle box was visible
    handle_correct: int
    draws: int  # scenes drawn (some without a usable door box are redrawn)


@dataclass(frozen=True)
class GoalUpdatingComparison:
    """Table II: per updating mode, the summed error of the final pose of every start pose."""

    errors: dict[str, FloatArray]
    starts: FloatArray  # (N, 3)
    reached: dict[str, npt.NDArray[np.bool_]]
    draws: int
    durations_s: dict[str, FloatArray] = field(default_factory=dict)


def _scene_spec(exp: DoorPoseExperiment) -> DoorSceneSpec:
    detections = PAPER_DETECTIONS.model_copy(update={"false_positive_rate": exp.false_positive_rate})
    return DoorSceneSpec(obstacles_per_scene=exp.obstacles_per_scene, detections=detections)


def _start_pose(rng: np.random.Generator, exp: DoorPoseExperiment) -> FloatArray:
    return np.array([rng.uniform(*exp.lateral_m), -rng.uniform(*exp.distance_m),
                     math.pi / 2 + math.radians(rng.uniform(*exp.heading_deg))])


def compare_fits(exp: DoorPoseExperiment, config: DoorbatchConfig) -> FitComparison:
    """Table I (module docstring). A scene is redrawn when no door box is usable (the paper's samples all
    had a detected door); a fit that gives no line on a usable box counts as a failure (error +inf).

    Raises:
        PipelineError: fewer than ``samples`` usable scenes in ``samples · max_attempts_factor`` draws.
    """
    rng = np.random.default_rng(exp.seed)
    spec = _scene_spec(exp)
    cfg = config.doorpose
    errors: dict[str, list[float]] = {f.value: [] for f in LineFit}
    checked = correct = draws = 0
    while len(errors[LineFit.RANSAC.value]) < exp.samples:
        draws += 1
        if draws > exp.samples * exp.max_attempts_factor:
            raise PipelineError(f"only {len(errors['ransac'])} usable door scenes in {draws - 1} draws")
        scene = make_door_scene(rng, spec)
        pose = _start_pose(rng, exp)
        obs = observe(scene, pose, rng)
        if door_box(usable_detections(obs.detections, cfg), scene.camera.width, cfg) is None:
            continue
        cam_to_base = scene.tf.lookup("base_link", CAMERA_FRAME, 0)
        truth = np.array([*scene.true_center, scene.true_yaw])
        seed = int(rng.integers(2**31))
        for fit in LineFit:
            door = estimate_door(scene.camera, obs.detections, obs.points_cam, cfg, np.random.default_rng(seed), fit)
            if door is None:
                errors[fit.value].append(math.inf)
                continue
            planar = to_planar(door, cam_to_base, pose)
            errors[fit.value].append(summed_pose_error(np.array([*planar.center, planar.yaw]), truth))
            if fit is LineFit.RANSAC and obs.handle_visible:
                checked += 1
                correct += int(door.handle_side.value == scene.true_handle_side(pose))
    return FitComparison({k: np.array(v) for k, v in errors.items()}, checked, correct, draws)


def odometry_noise(spec: OdometrySpec | None = None) -> OdometryNoise:
    """The simulator's wheel-odometry noise (its scenario defaults unless given)."""
    o = spec or OdometrySpec()
    return OdometryNoise(o.alpha1, o.alpha2, o.alpha3, o.alpha4, o.scale_error, o.yaw_drift_rad_per_m)


def compare_goal_updating(exp: DoorPoseExperiment, config: DoorbatchConfig) -> GoalUpdatingComparison:
    """Table II (module docstring). A start pose from which either run cannot estimate the door at the
    start is redrawn (the paper chose start poses from which the door was estimable).

    Raises:
        PipelineError: fewer than ``samples`` usable start poses in ``samples · max_attempts_factor`` draws.
    """
    rng = np.random.default_rng(exp.seed)
    spec = _scene_spec(exp)
    noise = odometry_noise()
    modes: tuple[GoalUpdating, ...] = ("initial", "continuous")
    errors: dict[str, list[float]] = {m: [] for m in modes}
    reached: dict[str, list[bool]] = {m: [] for m in modes}
    durations: dict[str, list[float]] = {m: [] for m in modes}
    starts: list[FloatArray] = []
    draws = 0
    while len(starts) < exp.samples:
        draws += 1
        if draws > exp.samples * exp.max_attempts_factor:
            raise PipelineError(f"only {len(starts)} usable start poses in {draws - 1} draws")
        scene = make_door_scene(rng, spec)
        start = _start_pose(rng, exp)
        seed = int(rng.integers(2**31))
        try:
            runs = {m: simulate_approach(scene, start, config.doorpose, noise, np.random.default_rng(seed), m)
                    for m in modes}
        except PipelineError:
            continue
        starts.append(start)
        for m, r in runs.items():
            errors[m].append(r.error)
            reached[m].append(r.reached)
            durations[m].append(r.duration_s)
    return GoalUpdatingComparison({m: np.array(v) for m, v in errors.items()}, np.array(starts),
                                  {m: np.array(v) for m, v in reached.items()}, draws,
                                  {m: np.array(v) for m, v in durations.items()})


def z_test_greater(a: npt.ArrayLike, b: npt.ArrayLike) -> tuple[float, float]:
    """One-sided two-sample z-test, H0: μ_a = μ_b, H1: μ_b > μ_a, the sample variances taken as known.

    Returns (z, p) with z = (x̄_b − x̄_a)/√(s_a²/n_a + s_b²/n_b) and p = 1 − Φ(z).
    """
    xa, xb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    se = math.sqrt(xa.var(ddof=1) / xa.size + xb.var(ddof=1) / xb.size)
    z = (xb.mean() - xa.mean()) / se if se > 0 else math.copysign(math.inf, xb.mean() - xa.mean())
    return float(z), float(stats.norm.sf(z))


def _rows(run: str, log: str, method: str, metric: str, value: float, unit: str, params: dict[str, object]
          ) -> MetricRow:
    return MetricRow(run, log, method, metric, float(value), unit, dict(params))


def fit_comparison_metrics(result: FitComparison, run: str, params: dict[str, object]) -> list[MetricRow]:
    """metrics.parquet rows: per fit the mean and std of the summed error, the count, failures, the
    z-test p-value against RANSAC; and the handle-side accuracy."""
    rows: list[MetricRow] = []
    ransac = result.errors[LineFit.RANSAC.value]
    for fit, err in result.errors.items():
        ok = err[np.isfinite(err)]
        rows.append(_rows(run, "simulated", fit, "door_pose_error_mean", ok.mean(), "1", params))
        rows.append(_rows(run, "simulated", fit, "door_pose_error_std", ok.std(ddof=1), "1", params))
        rows.append(_rows(run, "simulated", fit, "samples", err.size, "count", params))
        rows.append(_rows(run, "simulated", fit, "failures", int((~np.isfinite(err)).sum()), "count", params))
        if fit != LineFit.RANSAC.value:
            both = np.isfinite(err) & np.isfinite(ransac)
            rows.append(_rows(run, "simulated", fit, "z_test_p_vs_ransac",
                              z_test_greater(ransac[both], err[both])[1], "1", params))
    accuracy = result.handle_correct / result.handle_checked if result.handle_checked else math.nan
    rows.append(_rows(run, "simulated", "ransac", "handle_side_accuracy", accuracy, "1", params))
    return rows


def goal_updating_metrics(result: GoalUpdatingComparison, run: str, params: dict[str, object]
                          ) -> list[MetricRow]:
    """metrics.parquet rows: per mode the mean and std of the final summed error, the count, the
    fraction that reached the goal tolerance, and the z-test p-value of initial > continuous."""
    rows: list[MetricRow] = []
    for mode, err in result.errors.items():
        rows.append(_rows(run, "simulated", mode, "positioning_error_mean", err.mean(), "1", params))
        rows.append(_rows(run, "simulated", mode, "positioning_error_std", err.std(ddof=1), "1", params))
        rows.append(_rows(run, "simulated", mode, "samples", err.size, "count", params))
        rows.append(_rows(run, "simulated", mode, "reached_fraction", result.reached[mode].mean(), "1", params))
    p = z_test_greater(result.errors["continuous"], result.errors["initial"])[1]
    rows.append(_rows(run, "simulated", "initial", "z_test_p_vs_continuous", p, "1", params))
    return rows


def load_experiment(path: Path, base: DoorbatchConfig) -> tuple[DoorPoseExperiment, DoorbatchConfig]:
    """An experiment file and the config it runs with: its ``config:`` block merged over ``base``.

    Raises:
        ConfigError: unreadable, bad YAML, unknown key or wrong value (in the file or its config block).
    """
    data = read_yaml_mapping(path)
    try:
        exp = DoorPoseExperiment.model_validate(data)
        config = DoorbatchConfig.model_validate(deep_merge(base.as_dict(), exp.config))
    except ValidationError as err:
        raise ConfigError(f"{path}: {explain_validation(err)}") from err
    return exp, config


def experiment_metrics(exp: DoorPoseExperiment, config: DoorbatchConfig, run: str
                       ) -> tuple[list[MetricRow], FitComparison | GoalUpdatingComparison]:
    """Run an experiment (Table I or II) and its metrics.parquet rows."""
    params: dict[str, object] = {"experiment": exp.experiment, "samples": exp.samples, "seed": exp.seed}
    if exp.experiment == "doorpose_fit_comparison":
        fits = compare_fits(exp, config)
        return fit_comparison_metrics(fits, run, params), fits
    upd = compare_goal_updating(exp, config)
    return goal_updating_metrics(upd, run, params), upd


def door_pose_metrics(estimated: npt.ArrayLike, truth: npt.ArrayLike, handle_sides: list[str],
                      true_handle_sides: list[str], run: str, log: str, method: str,
                      params: dict[str, object] | None = None) -> list[MetricRow]:
    """metrics.parquet rows of door poses against their truth, row by row (the caller matches them):
    ``estimated`` and ``truth`` are (N, 4) centre x, y, normal yaw, width. Metrics: the mean summed error
    |Δx| + |Δy| + |Δθ| (Table I's), mean centre distance, mean |Δyaw|, mean |Δwidth|, the handle-side
    accuracy over rows whose true side is not ``none``, and the count."""
    est = np.asarray(estimated, dtype=np.float64).reshape(-1, 4)
    tru = np.asarray(truth, dtype=np.float64).reshape(-1, 4)
    p = params or {}
    dyaw = np.abs(wrap_angle(est[:, 2] - tru[:, 2]))
    summed = np.abs(est[:, 0] - tru[:, 0]) + np.abs(est[:, 1] - tru[:, 1]) + dyaw
    visible = [i for i, s in enumerate(true_handle_sides) if s != "none"]
    accuracy = (sum(handle_sides[i] == true_handle_sides[i] for i in visible) / len(visible)) if visible else math.nan
    n = est.shape[0]
    rows = [
        _rows(run, log, method, "door_pose_error_mean", summed.mean() if n else math.nan, "1", p),
        _rows(run, log, method, "door_center_error_mean", np.hypot(*(est[:, :2] - tru[:, :2]).T).mean()
              if n else math.nan, "m", p),
        _rows(run, log, method, "door_yaw_error_mean", dyaw.mean() if n else math.nan, "rad", p),
        _rows(run, log, method, "door_width_error_mean", np.abs(est[:, 3] - tru[:, 3]).mean() if n else math.nan,
              "m", p),
        _rows(run, log, method, "handle_side_accuracy", accuracy, "1", p),
        _rows(run, log, method, "door_poses", n, "count", p),
    ]
    return rows
