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
ROS 1 amcl's ``diff`` and ``omni`` models (``odom_model_type``, its default before ``diff-corrected``) draw each
noise with its α-sum as the standard deviation instead, e.g. ε1 ~ N(0, (α1 r1² + α2 δtrans²)²): ``sums_as_std``.

For holonomic bases, :func:`sample_motion_model_omni` is Nav2 AMCL's ``OmniMotionModel``: the increment is a
translation δtrans along the bearing β = atan2(Δy, Δx) − θ (odom frame) and a rotation δrot, each particle
drawing a noisy translation, rotation and a sideways "strafe" along its own bearing θ_i + β,

    δ̂trans = δtrans + ε_t,  ε_t ~ N(0, α3 δtrans² + α4 δrot²)
    δ̂rot   = δrot + ε_r,    ε_r ~ N(0, α1 δrot² + α2 δtrans²)
    δ̂strafe = ε_s,          ε_s ~ N(0, α4 δrot² + α5 δtrans²)
    x ← x + δ̂trans cos b + δ̂strafe sin b,  y ← y + δ̂trans sin b − δ̂strafe cos b,  θ ← θ + δ̂rot,  b = θ + β.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.odometry import MIN_TRANS_FOR_BEARING_M, increment_variances, odometry_increments
from doorbatch.geometry.rotations import wrap_angle

FloatArray = npt.NDArray[np.float64]


def increment_noise_std(rot1: float, trans: float, rot2: float, alphas: Sequence[float], sums_as_std: bool = False
                        ) -> tuple[float, float, float]:
    """Standard deviations of the noise on (δrot1, δtrans, δrot2) for one increment (AMCL's diff model; with
    ``sums_as_std``, ROS 1 amcl's uncorrected ``diff``: the α-sums themselves)."""
    sums = np.array(increment_variances(rot1, trans, rot2, alphas), dtype=np.float64)
    sd = sums if sums_as_std else np.sqrt(sums)
    return float(sd[0]), float(sd[1]), float(sd[2])


def _checked_poses(pose: npt.ArrayLike, alphas: Sequence[float], n_alphas: int) -> FloatArray:
    """``pose`` as an (N, 3) float array, once it and the number of alphas are what a model needs."""
    p = np.asarray(pose, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"pose must be (N, 3), got shape {p.shape}")
    if len(alphas) != n_alphas:
        raise ValueError(f"need {('four', 'five')[n_alphas - 4]} alphas (alpha1..alpha{n_alphas}), got {len(alphas)}")
    return p


def sample_motion_model_odometry(pose: npt.ArrayLike, odom_prev: npt.ArrayLike, odom_now: npt.ArrayLike,
                                 alphas: Sequence[float], rng: np.random.Generator, sums_as_std: bool = False
                                 ) -> FloatArray:
    """Move every particle by a noisy copy of the odometry increment odom_prev → odom_now.

    Args:
        pose: (N, 3) particle poses (x, y, yaw) in the map frame.
        odom_prev: (3,) odometry pose (odom frame) at the last filter update.
        odom_now: (3,) odometry pose now.
        alphas: (α1, α2, α3, α4): rotation noise from rotation, rotation noise from translation, translation
            noise from translation, translation noise from rotation (Nav2 alpha1..alpha4).
        rng: random generator (3·N standard normal draws, in one call).
        sums_as_std: ROS 1 amcl's ``diff`` model: each α-sum is the noise's standard deviation (module docstring).

    Returns:
        (N, 3) new poses, yaw wrapped to (−π, π].

    Raises:
        ValueError: ``pose`` is not (N, 3) or there are not four alphas.
    """
    p = _checked_poses(pose, alphas, 4)
    odo = np.stack([np.asarray(odom_prev, dtype=np.float64), np.asarray(odom_now, dtype=np.float64)])
    inc = odometry_increments(odo[:, 0], odo[:, 1], odo[:, 2], min_trans_m=MIN_TRANS_FOR_BEARING_M)
    rot1, trans, rot2 = float(inc.rot1[0]), float(inc.trans[0]), float(inc.rot2[0])
    sd = np.array(increment_noise_std(rot1, trans, rot2, alphas, sums_as_std))
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


def sample_motion_model_omni(pose: npt.ArrayLike, odom_prev: npt.ArrayLike, odom_now: npt.ArrayLike,
                             alphas: Sequence[float], rng: np.random.Generator, sums_as_std: bool = False
                             ) -> FloatArray:
    """Move every particle by a noisy copy of the odometry increment, Nav2 AMCL's omnidirectional model.

    Arguments, result and errors as :func:`sample_motion_model_odometry`, except that ``alphas`` are five:
    Nav2's ``alpha1``..``alpha5`` in the roles the module docstring gives them (α5: strafe noise from translation).
    ROS 1 amcl's ``omni`` / ``omni-corrected`` are this model with its α1 and α4 swapped (``sums_as_std`` for
    ``omni``).
    """
    p = _checked_poses(pose, alphas, 5)
    a1, a2, a3, a4, a5 = (float(a) for a in alphas)
    prev = np.asarray(odom_prev, dtype=np.float64).reshape(3)
    now = np.asarray(odom_now, dtype=np.float64).reshape(3)
    dx, dy = now[0] - prev[0], now[1] - prev[1]
    trans = float(np.hypot(dx, dy))
    rot = float(wrap_angle(now[2] - prev[2]))
    sums = np.array([a3 * trans**2 + a4 * rot**2, a1 * rot**2 + a2 * trans**2, a4 * rot**2 + a5 * trans**2])
    sd = sums if sums_as_std else np.sqrt(sums)
    eps = rng.standard_normal((p.shape[0], 3)) * sd
    trans_hat = trans + eps[:, 0]
    strafe_hat = eps[:, 2]
    # At a standstill atan2(0, 0) = 0 gives β = −θ_prev; the translation is then noise only, in any direction.
    bearing = p[:, 2] + float(wrap_angle(np.arctan2(dy, dx) - prev[2]))
    c, s = np.cos(bearing), np.sin(bearing)
    out = np.empty_like(p)
    out[:, 0] = p[:, 0] + trans_hat * c + strafe_hat * s
    out[:, 1] = p[:, 1] + trans_hat * s - strafe_hat * c
    out[:, 2] = wrap_angle(p[:, 2] + rot + eps[:, 1])
    return out
