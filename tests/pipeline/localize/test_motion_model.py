"""Odometry motion model (Probabilistic Robotics Table 5.6, Nav2 AMCL's diff model): sample statistics."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative
from doorbatch.pipeline.localize.motion_model import (
    increment_noise_std,
    sample_motion_model_odometry,
    sample_motion_model_omni,
)

ALPHAS = (0.02, 0.01, 0.03, 0.01)


def odom_after(prev: tuple[float, float, float], rot1: float, trans: float, rot2: float) -> np.ndarray:
    """The odometry pose reached from ``prev`` by the increment (rot1, trans, rot2)."""
    x, y, yaw = prev
    return np.array([x + trans * math.cos(yaw + rot1), y + trans * math.sin(yaw + rot1), yaw + rot1 + rot2])


def test_samples_have_the_alpha_model_means_and_variances() -> None:
    rot1, trans, rot2 = 0.3, 1.0, -0.2
    prev = (1.0, 2.0, 0.5)
    n = 200_000
    out = sample_motion_model_odometry(np.zeros((n, 3)), prev, odom_after(prev, rot1, trans, rot2), ALPHAS,
                                       np.random.default_rng(1))
    rot1_hat = np.arctan2(out[:, 1], out[:, 0])  # particles start at the origin heading 0
    trans_hat = np.hypot(out[:, 0], out[:, 1])
    rot2_hat = wrap_angle(out[:, 2] - rot1_hat)
    a1, a2, a3, a4 = ALPHAS
    expected_sd = (math.sqrt(a1 * rot1**2 + a2 * trans**2), math.sqrt(a3 * trans**2 + a4 * (rot1**2 + rot2**2)),
                   math.sqrt(a1 * rot2**2 + a2 * trans**2))
    assert increment_noise_std(rot1, trans, rot2, ALPHAS) == pytest.approx(expected_sd)
    for sample, mean, sd in zip((rot1_hat, trans_hat, rot2_hat), (rot1, trans, rot2), expected_sd, strict=True):
        assert abs(sample.mean() - mean) < 5 * sd / math.sqrt(n)
        assert sample.std() == pytest.approx(sd, rel=0.01)
    corr = np.corrcoef(np.stack([rot1_hat, trans_hat, rot2_hat]))
    assert np.all(np.abs(corr[np.triu_indices(3, 1)]) < 0.01)  # independent draws


def test_without_noise_particles_move_by_the_odometry_increment_in_their_own_frame() -> None:
    rng = np.random.default_rng(2)
    pose = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    prev, now = np.array([3.0, -1.0, 2.5]), np.array([3.4, -0.7, -2.9])
    out = sample_motion_model_odometry(pose, prev, now, (0.0, 0.0, 0.0, 0.0), rng)
    expected = compose(pose, relative(prev, now))
    assert np.allclose(out[:, :2], expected[:, :2], atol=1e-12)
    assert np.allclose(wrap_angle(out[:, 2] - expected[:, 2]), 0.0, atol=1e-12)


def test_backward_driving_gets_the_same_rotation_noise_as_forward() -> None:
    n = 100_000
    fwd = sample_motion_model_odometry(np.zeros((n, 3)), (0, 0, 0), (0.5, 0, 0), ALPHAS, np.random.default_rng(3))
    back = sample_motion_model_odometry(np.zeros((n, 3)), (0, 0, 0), (-0.5, 0, 0), ALPHAS, np.random.default_rng(3))
    expected_yaw_sd = math.sqrt(2 * ALPHAS[1]) * 0.5  # only the α2·trans² terms: δrot1 = π counts as 0
    assert fwd[:, 2].std() == pytest.approx(expected_yaw_sd, rel=0.02)
    assert wrap_angle(back[:, 2]).std() == pytest.approx(expected_yaw_sd, rel=0.02)
    assert back[:, 0].mean() == pytest.approx(-0.5, abs=2e-3)


def test_rotation_in_place_has_no_bearing() -> None:
    """Below 1 cm of translation δrot1 = 0 (AMCL): a pure turn moves no particle sideways."""
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, np.pi / 2]])
    out = sample_motion_model_odometry(pose, (0, 0, 0), (0.005, 0.005, 1.0), (0, 0, 0, 0), np.random.default_rng(4))
    step = 0.005 * math.sqrt(2)
    assert np.allclose(out[0], [step, 0.0, 1.0])
    assert np.allclose(out[1], [1.0, 1.0 + step, np.pi / 2 + 1.0])


def test_bad_shapes_are_rejected() -> None:
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        sample_motion_model_odometry(np.zeros(3), (0, 0, 0), (1, 0, 0), ALPHAS, np.random.default_rng())
    with pytest.raises(ValueError, match="four alphas"):
        sample_motion_model_odometry(np.zeros((1, 3)), (0, 0, 0), (1, 0, 0), (0.1, 0.1), np.random.default_rng())


OMNI_ALPHAS = (0.02, 0.01, 0.03, 0.015, 0.04)


def test_omni_model_without_noise_moves_particles_by_the_increment_in_their_own_frame() -> None:
    rng = np.random.default_rng(5)
    pose = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    prev, now = np.array([3.0, -1.0, 2.5]), np.array([2.6, -1.3, -2.9])  # sideways and backwards, turning
    out = sample_motion_model_omni(pose, prev, now, (0.0,) * 5, rng)
    expected = compose(pose, relative(prev, now))
    assert np.allclose(out[:, :2], expected[:, :2], atol=1e-12)
    assert np.allclose(wrap_angle(out[:, 2] - expected[:, 2]), 0.0, atol=1e-12)


def test_omni_samples_have_nav2s_translation_rotation_and_strafe_variances() -> None:
    """Particles at the origin heading 0; the odometry moved 0.8 m at bearing 0.6 rad off its heading and
    turned 0.4 rad: the draws along and across that bearing and in yaw have Nav2 OmniMotionModel's spreads."""
    trans, bearing, rot = 0.8, 0.6, 0.4
    prev = np.array([1.0, 2.0, 0.3])
    now = prev + np.array([trans * math.cos(prev[2] + bearing), trans * math.sin(prev[2] + bearing), rot])
    n = 200_000
    out = sample_motion_model_omni(np.zeros((n, 3)), prev, now, OMNI_ALPHAS, np.random.default_rng(6))
    along = out[:, 0] * math.cos(bearing) + out[:, 1] * math.sin(bearing)
    across = out[:, 0] * math.sin(bearing) - out[:, 1] * math.cos(bearing)
    a1, a2, a3, a4, a5 = OMNI_ALPHAS
    expected_sd = (math.sqrt(a3 * trans**2 + a4 * rot**2), math.sqrt(a4 * rot**2 + a5 * trans**2),
                   math.sqrt(a1 * rot**2 + a2 * trans**2))
    for sample, mean, sd in zip((along, across, out[:, 2]), (trans, 0.0, rot), expected_sd, strict=True):
        assert abs(sample.mean() - mean) < 5 * sd / math.sqrt(n)
        assert sample.std() == pytest.approx(sd, rel=0.01)


def test_a_sideways_step_costs_the_omni_model_no_turn() -> None:
    """A holonomic base strafing 0.5 m: the differential model reads a quarter turn there and a quarter turn
    back (rotation noise α1·(π/2)² twice), the omnidirectional one only the α2·trans² of the step."""
    n = 100_000
    prev, now = (0.0, 0.0, 0.0), (0.0, 0.5, 0.0)
    omni = sample_motion_model_omni(np.zeros((n, 3)), prev, now, OMNI_ALPHAS, np.random.default_rng(7))
    diff = sample_motion_model_odometry(np.zeros((n, 3)), prev, now, OMNI_ALPHAS[:4], np.random.default_rng(7))
    assert omni[:, 2].std() == pytest.approx(math.sqrt(OMNI_ALPHAS[1]) * 0.5, rel=0.02)
    assert diff[:, 2].std() > 3 * omni[:, 2].std()


def test_the_omni_model_needs_five_alphas() -> None:
    with pytest.raises(ValueError, match="five alphas"):
        sample_motion_model_omni(np.zeros((1, 3)), (0, 0, 0), (1, 0, 0), ALPHAS, np.random.default_rng())


def test_ros1_amcl_diff_draws_the_alpha_sums_as_standard_deviations() -> None:
    """ROS 1 amcl's ``odom_model_type: diff`` (amcl_odom.cpp, ODOM_MODEL_DIFF): pf_ran_gaussian(α1 r1² + α2 t²),
    the sum itself as σ, where diff-corrected takes its square root."""
    rot1, trans, rot2 = 0.3, 0.5, -0.2
    prev = (0.0, 0.0, 0.0)
    n = 200_000
    out = sample_motion_model_odometry(np.zeros((n, 3)), prev, odom_after(prev, rot1, trans, rot2), ALPHAS,
                                       np.random.default_rng(2), sums_as_std=True)
    rot1_hat = np.arctan2(out[:, 1], out[:, 0])
    trans_hat = np.hypot(out[:, 0], out[:, 1])
    rot2_hat = wrap_angle(out[:, 2] - rot1_hat)
    a1, a2, a3, a4 = ALPHAS
    expected_sd = (a1 * rot1**2 + a2 * trans**2, a3 * trans**2 + a4 * (rot1**2 + rot2**2), a1 * rot2**2 + a2 * trans**2)
    for sample, sd in zip((rot1_hat, trans_hat, rot2_hat), expected_sd, strict=True):
        assert sample.std() == pytest.approx(sd, rel=0.01)
    assert expected_sd[1] < 0.1 * increment_noise_std(rot1, trans, rot2, ALPHAS)[1]  # a real difference here


def test_ros1_amcl_omni_draws_the_alpha_sums_as_standard_deviations() -> None:
    """ROS 1's ``omni`` is the same model with the α-sums as σ (and its α1 and α4 swapped by the translation)."""
    trans, bearing, rot = 0.8, 0.6, 0.4
    prev = np.array([1.0, 2.0, 0.3])
    now = prev + np.array([trans * math.cos(prev[2] + bearing), trans * math.sin(prev[2] + bearing), rot])
    n = 200_000
    out = sample_motion_model_omni(np.zeros((n, 3)), prev, now, OMNI_ALPHAS, np.random.default_rng(7),
                                   sums_as_std=True)
    along = out[:, 0] * math.cos(bearing) + out[:, 1] * math.sin(bearing)
    across = out[:, 0] * math.sin(bearing) - out[:, 1] * math.cos(bearing)
    a1, a2, a3, a4, a5 = OMNI_ALPHAS
    expected_sd = (a3 * trans**2 + a4 * rot**2, a4 * rot**2 + a5 * trans**2, a1 * rot**2 + a2 * trans**2)
    for sample, sd in zip((along, across, out[:, 2]), expected_sd, strict=True):
        assert sample.std() == pytest.approx(sd, rel=0.01)
