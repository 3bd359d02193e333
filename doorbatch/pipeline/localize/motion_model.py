"""Odometry motion model for particles: Probabilistic Robotics Table 5.6 as Nav2 AMCL's ``diff`` model.

The reported odometry increment between two odometry poses is decomposed into (δrot1, δtrans, δrot2)
(:mod:`doorbatch.geometry.odometry`; pure rotation below 0.01 m, as AMCL). Each particle then moves by its
own noisy copy of it,

    δ̂rot1  = δrot1 − ε1,    ε1 ~ N(0, α1 r1² + α2 δtrans²)
    δ̂trans = δtrans − ε2,   ε2 ~ N(0, α3 δtrans² + α4 (r1² + r2²))
    δ̂rot2  = δrot2 − ε3,    ε3 ~ N(0, α1 r2² + α2 δtrans²)
    x ← x + δ̂trans cos(θ + δ̂rot1),  y ← y + δ̂trans sin(θ + δ̂rot1),  θ ← θ + δ̂rot1 + δ̂rot2

where, as in nav2_amcl ``DifferentialMotionModel::odometryUpdate``, the rotation terms of the variances are
r = min(|δrot|, π − |δrot|), so that driving backwards (δrot1 ≈ ±π) costs no more rotation noise than
driving forwards. The α's are variances per unit² (the book's and AMCL's convention, not standard deviations).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.odometry import MIN_TRANS_FOR_BEARING_M, increment_variances, odometry_increments
from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]


def increment_noise_std(rot1: float, trans: float, rot2: float, alphas: Sequence[float]
                        ) -> tuple[float, float, float]:
    """Standard deviations of the noise on (δrot1, δtrans, δrot2) for one increment (AMCL's diff model)."""
    var_rot1, var_trans, var_rot2 = increment_variances(rot1, trans, rot2, alphas)
    return float(np.sqrt(var_rot1)), float(np.sqrt(var_trans)), float(np.sqrt(var_rot2))


def sample_motion_model_odometry(pose: npt.ArrayLike, odom_prev: npt.ArrayLike, odom_now: npt.ArrayLike,
                                 alphas: Sequence[float], rng: np.random.Generator) -> FloatArray:
    """Move every particle by a noisy copy of the odometry increment odom_prev → odom_now.

    Args:
        pose: (N, 3) particle poses (x, y, yaw) in the map frame.
        odom_prev: (3,) odometry pose (odom frame) at the last filter update.
        odom_now: (3,) odometry pose now.
        alphas: (α1, α2, α3, α4): rotation noise from rotation, rotation noise from translation, translation
            noise from translation, translation noise from rotation (Nav2 alpha1..alpha4).
        rng: random generator (3·N standard normal draws, in one call).

    Returns:
        (N, 3) new poses, yaw wrapped to (−π, π].

    Raises:
        ValueError: ``pose`` is not (N, 3) or there are not four alphas.
    """
    p = np.asarray(pose, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"pose must be (N, 3), got shape {p.shape}")
    if len(alphas) != 4:
        raise ValueError(f"need four alphas (alpha1..alpha4), got {len(alphas)}")
    odo = np.stack([np.asarray(odom_prev, dtype=np.float64), np.asarray(odom_now, dtype=np.float64)])
    inc = odometry_increments(odo[:, 0], odo[:, 1], odo[:, 2], min_trans_m=MIN_TRANS_FOR_BEARING_M)
    rot1, trans, rot2 = float(inc.rot1[0]), float(inc.trans[0]), float(inc.rot2[0])
    sd = np.array(increment_noise_std(rot1, trans, rot2, alphas))
    eps = rng.standard_normal((p.shape[0], 3)) * sd
    rot1_hat = rot1 - eps[:, 0]
    trans_hat = trans - eps[:, 1]
    rot2_hat = rot2 - eps[:, 2]
    heading = p[:, 2] + rot1_hat
    out = np.empty_like(p)
    out[:, 0] = p[:, 0] + trans_hat * np.cos(heading)
    out[:, 1] = p[:, 1] + trans_hat * np.sin(heading)
    out[:, 2] = wrap_angle(heading + rot2_hat)
    return out
