"""Odometry α calibration recovers the α of simulated odometry."""

from __future__ import annotations

import numpy as np

from doorbatch.pipeline.localize.calibrate import estimate_alphas
from doorbatch.sim.motion import OdometryNoise, drift_poses


def test_alphas_of_simulated_odometry_are_recovered() -> None:
    rng = np.random.default_rng(3)
    n = 20000
    # a wandering path: steps of 0.05–0.3 m and turns of up to ±20°
    steps = rng.uniform(0.05, 0.3, n)
    turns = rng.uniform(-0.35, 0.35, n)
    yaw = np.cumsum(turns)
    ref = np.stack([np.cumsum(steps * np.cos(yaw)), np.cumsum(steps * np.sin(yaw)), yaw], 1)
    noise = OdometryNoise(alpha1=0.02, alpha2=0.005, alpha3=0.03, alpha4=0.001)
    odo = drift_poses(ref, noise, rng)
    fit = estimate_alphas(odo, ref)
    np.testing.assert_allclose([fit.alpha1, fit.alpha2, fit.alpha3], [0.02, 0.005, 0.03], rtol=0.15)
    # α4 (translation noise from rotation) contributes little next to α3 on such a path: weaker identification
    np.testing.assert_allclose(fit.alpha4, 0.001, rtol=0.4)
