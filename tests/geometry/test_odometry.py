"""The share of a path driven across the heading: zero for any arc a differential base drives, one for a strafe."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.geometry.odometry import sideways_share, sweep_smear_m


def _arc(curvature: float, length_m: float, n: int, yaw0: float) -> np.ndarray:
    s = np.linspace(0.0, length_m, n)
    yaw = yaw0 + curvature * s
    if abs(curvature) < 1e-9:
        x, y = s * math.cos(yaw0), s * math.sin(yaw0)
    else:
        x = (np.sin(yaw) - math.sin(yaw0)) / curvature
        y = (math.cos(yaw0) - np.cos(yaw)) / curvature
    return np.stack([x, y, yaw], axis=1)


@settings(max_examples=40, deadline=None)
@given(st.floats(-2.0, 2.0), st.floats(1.0, 20.0), st.integers(50, 2000), st.floats(-math.pi, math.pi),
       st.booleans())
def test_any_arc_forwards_or_backwards_moves_nothing_sideways(curvature: float, length_m: float, n: int,
                                                              yaw0: float, backwards: bool) -> None:
    p = _arc(curvature, length_m, n, yaw0)
    if backwards:  # the same arcs driven in reverse: heading flipped, bearing along the axis still
        p[:, 2] += math.pi
    assert sideways_share(p[:, 0], p[:, 1], p[:, 2], 0.1) < 1e-6


def test_a_strafe_is_all_sideways_and_a_crab_walk_its_sine() -> None:
    s = np.linspace(0.0, 5.0, 501)
    assert sideways_share(0 * s, s, 0 * s, 0.1) == 1.0  # facing +x, moving along +y
    crab = math.radians(30.0)
    assert math.isclose(sideways_share(s * math.cos(crab), s * math.sin(crab), 0 * s, 0.1), 0.5, rel_tol=1e-9)


def test_a_robot_standing_with_jittering_odometry_makes_no_step() -> None:
    """An EKF's odometry of a standing robot wanders by millimetres in every direction: no step, no share."""
    rng = np.random.default_rng(0)
    jitter = rng.normal(0.0, 0.002, (5000, 3))
    assert math.isnan(sideways_share(jitter[:, 0], jitter[:, 1], jitter[:, 2], 0.1))
    drive = _arc(0.3, 10.0, 2000, 0.0) + rng.normal(0.0, 0.002, (2000, 3))  # and while it drives, a little
    assert sideways_share(drive[:, 0], drive[:, 1], drive[:, 2], 0.1) < 0.05


def test_the_sweep_smear_of_a_robot_that_spins_now_and_then_shows_at_a_high_quantile() -> None:
    """Straight at 0.5 m/s 80 % of the time, spinning in place at 2 rad/s the rest: the median turn rate is 0, so a
    0.2 s sweep smears a 5 m beam end by (0.5 + 0)·0.2 = 0.1 m at the median; at the 0.9 quantile the spins show,
    (0.5 + 2·5)·0.2 = 2.1 m (the speed's 0.9 quantile is still 0.5)."""
    t = np.arange(501) * 20_000_000  # 50 Hz
    spinning = (np.arange(500) % 10) >= 8
    step = np.where(spinning[:, None], [0.0, 0.0, 2.0 * 0.02], [0.5 * 0.02, 0.0, 0.0])
    poses = np.concatenate([[[0.0, 0.0, 0.0]], np.cumsum(step, axis=0)])  # x along the heading 0 while straight
    poses[1:, 0] = np.cumsum(np.where(spinning, 0.0, 0.5 * 0.02))
    assert sweep_smear_m(0.2, t, poses, 5.0) == pytest.approx(0.1)
    assert sweep_smear_m(0.2, t, poses, 5.0, quantile=0.9) == pytest.approx(2.1)
