"""Odometry α calibration recovers the α of simulated odometry."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import compose
from doorbatch.pipeline.localize.calibrate import OdometryAlphas, estimate_alphas, estimate_omni_alphas
from doorbatch.sim.motion import OdometryNoise, drift_poses

NOISE = OdometryNoise(alpha1=0.02, alpha2=0.005, alpha3=0.03, alpha4=0.001)


def _fit_on_a_wandering_path(seed: int, spin_share: float) -> OdometryAlphas:
    """α fitted on 20,000 steps of 0.05–0.3 m with turns of up to ±20°; a ``spin_share`` of them are turns on the
    spot of 17–69° instead (no translation)."""
    rng = np.random.default_rng(seed)
    n = 20000
    steps = rng.uniform(0.05, 0.3, n)
    turns = rng.uniform(-0.35, 0.35, n)
    spin: npt.NDArray[np.bool_] = rng.random(n) < spin_share
    steps[spin] = 0.0
    turns[spin] = rng.choice([-1.0, 1.0], int(spin.sum())) * rng.uniform(0.3, 1.2, int(spin.sum()))
    yaw = np.cumsum(turns)
    ref = np.stack([np.cumsum(steps * np.cos(yaw)), np.cumsum(steps * np.sin(yaw)), yaw], 1)
    return estimate_alphas(drift_poses(ref, NOISE, rng), ref)


def test_alphas_of_simulated_odometry_are_recovered() -> None:
    fit = _fit_on_a_wandering_path(3, 0.0)
    assert fit.increments == 19999  # 20,000 poses, each step at least 5 cm: no increment left out as standing still
    np.testing.assert_allclose([fit.alpha1, fit.alpha2, fit.alpha3], [0.02, 0.005, 0.03], rtol=0.15)
    # α4 (translation noise from rotation) contributes little next to α3 on such a path: weaker identification
    np.testing.assert_allclose(fit.alpha4, 0.001, rtol=0.4)


def test_turns_in_place_do_not_count_a_millimetre_bearing_as_a_rotation_error() -> None:
    """A robot that turns on the spot: the reference does not move, the odometry reports the α4 translation noise
    of the turn, centimetres forwards or backwards. A backwards one decomposes into δrot1 = π against the
    reference's 0. Compared as pure rotations (the motion model's rule below 1 cm), the fit is unchanged; compared
    bearing by bearing, α1 came out as 5 here (and 400 on the sample's mapping passes)."""
    fit = _fit_on_a_wandering_path(5, 0.1)
    assert fit.increments == 19999  # the turns on the spot count too (more than 1°): all 19,999 increments
    np.testing.assert_allclose([fit.alpha1, fit.alpha2, fit.alpha3], [0.02, 0.005, 0.03], rtol=0.2)
    np.testing.assert_allclose(fit.alpha4, 0.001, rtol=0.4)


def test_alpha4_charges_both_rotations_of_an_increment() -> None:
    """Steps that turn, drive a chord and turn again (δrot1 and δrot2 both ±20°): the translation noise from rotation
    is α4·(δrot1² + δrot2²) (the motion model's), so α4 comes out right only when both rotations are counted."""
    noise = OdometryNoise(alpha1=0.02, alpha2=0.005, alpha3=0.01, alpha4=0.01)
    rng = np.random.default_rng(11)
    n = 20000
    rot1, trans, rot2 = rng.uniform(-0.35, 0.35, n), rng.uniform(0.05, 0.3, n), rng.uniform(-0.35, 0.35, n)
    ref = [np.zeros(3)]
    for r1, t, r2 in zip(rot1, trans, rot2, strict=True):
        ref.append(compose(compose(ref[-1], [0.0, 0.0, r1]), [t, 0.0, r2]))
    path = np.array(ref)
    fit = estimate_alphas(drift_poses(path, noise, rng), path)
    np.testing.assert_allclose([fit.alpha3, fit.alpha4], [0.01, 0.01], rtol=0.25)


def test_omni_alphas_of_simulated_holonomic_odometry_are_recovered() -> None:
    """A holonomic base: 20,000 steps of 0.05-0.3 m in any direction of its frame, turning up to ±20°; its odometry
    increments carry Nav2 OmniMotionModel noise of known α (along, across and in heading)."""
    alphas = (0.02, 0.005, 0.03, 0.01, 0.015)
    a1, a2, a3, a4, a5 = alphas
    rng = np.random.default_rng(8)
    n = 20000
    trans = rng.uniform(0.05, 0.3, n)
    bearing = rng.uniform(-np.pi, np.pi, n)
    rot = rng.uniform(-0.35, 0.35, n)
    along = trans + rng.normal(0.0, 1.0, n) * np.sqrt(a3 * trans**2 + a4 * rot**2)
    across = rng.normal(0.0, 1.0, n) * np.sqrt(a4 * rot**2 + a5 * trans**2)
    turn = rot + rng.normal(0.0, 1.0, n) * np.sqrt(a1 * rot**2 + a2 * trans**2)
    odo_steps = np.stack([trans * np.cos(bearing), trans * np.sin(bearing), rot], 1)
    ref_steps = np.stack([along * np.cos(bearing) + across * np.sin(bearing),
                          along * np.sin(bearing) - across * np.cos(bearing), turn], 1)
    odo, ref = np.zeros((n + 1, 3)), np.zeros((n + 1, 3))
    for k in range(n):
        odo[k + 1] = compose(odo[k], odo_steps[k])
        ref[k + 1] = compose(ref[k], ref_steps[k])
    fit = estimate_omni_alphas(odo, ref)
    assert fit.increments == n
    np.testing.assert_allclose([fit.alpha1, fit.alpha2, fit.alpha3, fit.alpha4, fit.alpha5], alphas, rtol=0.15)
