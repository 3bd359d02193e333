"""The white noise of a reference pose topic, told apart from the robot's motion and the odometry's own noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.io.recording import PoseSeries, Recording, ScanSet
from doorbatch.pipeline.mapping import reference_jitter_notes
from doorbatch.pipeline.poses.pose_jitter import pose_jitter


def _drive(n: int, dt_s: float) -> np.ndarray:
    """A robot weaving down a corridor at 0.5 m/s: speed and turn rate change smoothly."""
    t = np.arange(n) * dt_s
    yaw = 0.6 * np.sin(0.4 * t)
    speed = 0.5 + 0.2 * np.sin(0.3 * t)
    x = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.cos(yaw[:-1]) * dt_s)])
    y = np.concatenate([[0.0], np.cumsum(speed[:-1] * np.sin(yaw[:-1]) * dt_s)])
    return np.stack([x, y, yaw], axis=1)


@pytest.mark.parametrize(("sigma_m", "sigma_rad"), [(0.01, 0.01), (0.003, 0.002), (0.02, 0.0)])
def test_white_noise_on_a_50_hz_ground_truth_is_measured(sigma_m: float, sigma_rad: float) -> None:
    rng = np.random.default_rng(1)
    truth = _drive(3000, 0.02)
    noisy = truth + rng.normal(0.0, [sigma_m, sigma_m, sigma_rad], truth.shape)
    for odometry in (None, truth + np.cumsum(rng.normal(0.0, 1e-4, truth.shape), axis=0)):  # slow drift
        jitter = pose_jitter(noisy, odometry)
        assert jitter.xy_m == pytest.approx(sigma_m, rel=0.1)
        assert jitter.yaw_rad == pytest.approx(sigma_rad, rel=0.1, abs=2e-4)


def test_an_exact_reference_is_quiet_beside_jittering_odometry_or_at_a_low_rate() -> None:
    rng = np.random.default_rng(2)
    truth = _drive(3000, 0.02)
    odometry = truth + rng.normal(0.0, [0.004, 0.004, 0.003], truth.shape)  # a simulator's white odometry noise
    jitter = pose_jitter(truth, odometry)
    assert jitter.xy_m < 2e-4 and jitter.yaw_rad < 2e-4
    sparse = _drive(200, 1.0)  # 1 Hz: real accelerations change a step by centimetres, the odometry agrees
    jitter = pose_jitter(sparse, sparse + np.linspace(0.0, 0.01, len(sparse))[:, None])
    assert jitter.xy_m < 1e-4 and jitter.yaw_rad < 1e-4
    assert math.isnan(pose_jitter(sparse[:3]).xy_m)


def test_mapping_warns_of_a_jittering_reference_and_names_scan_matching() -> None:
    rng = np.random.default_rng(3)
    truth = _drive(2000, 0.02)
    stamps = np.arange(len(truth), dtype=np.int64) * 20_000_000
    scans = ScanSet(np.zeros(0, dtype=np.int64), [], *(np.zeros(0) for _ in range(4)), np.zeros((0, 2, 3)), "laser")
    odometry = PoseSeries(stamps, truth, "odom")

    def rec(reference: np.ndarray) -> Recording:
        return Recording("p3d.bag", scans, odometry, PoseSeries(stamps, reference, "map"))

    config = DoorbatchConfig()
    assert reference_jitter_notes([rec(truth)], config) == []
    notes = reference_jitter_notes([rec(truth + rng.normal(0.0, [0.01, 0.01, 0.01], truth.shape))], config)
    assert len(notes) == 1 and "p3d.bag" in notes[0] and "--pose-source scanmatch" in notes[0]
    assert "σ ≈ 1.0 cm, 0.5" in notes[0]  # 0.01 rad = 0.57°, measured within a few per cent
