"""Calibrate the odometry motion model's α from a log with a reference trajectory: α1–α4 of the differential
model, or α1–α5 of the omnidirectional one (:func:`estimate_omni_alphas`).

Both trajectories are decomposed into increments (δrot1, δtrans, δrot2) between consecutive samples
(Probabilistic Robotics Table 5.6). The model says the odometry's increment errors are zero-mean with
variances σ²_rot = α1·r² + α2·δtrans² and σ²_trans = α3·δtrans² + α4·(r1² + r2²), r = min(|δrot|, π − |δrot|)
as in the localizers' model (Nav2 AMCL's; a step backwards is no noisier than one forwards). With the squared
errors as observations of those variances, the α are a non-negative least-squares fit. Systematic errors
(a wheel-radius scale, a heading drift) count as noise here, which is what a particle filter needs: its
spread must cover them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.optimize import nnls

from doorbatch.geometry.odometry import (
    MIN_TRANS_FOR_BEARING_M,
    Increments,
    odometry_increments,
    rotation_noise_magnitude,
)
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import relative


@dataclass(frozen=True)
class OdometryAlphas:
    """Fitted α1..α4 (Nav2 AMCL alpha1..alpha4) and the number of increments used."""

    alpha1: float
    alpha2: float
    alpha3: float
    alpha4: float
    increments: int


def _as_pure_rotations_below_bearing_threshold(odo: Increments, ref: Increments) -> tuple[Increments, Increments]:
    """Both decompositions with every step that either moves less than ``MIN_TRANS_FOR_BEARING_M`` taken as a
    pure rotation (δrot1 = 0, δrot2 = the whole turn), as the localizers' motion model takes such an odometry
    step (Nav2 AMCL). A millimetre's bearing is noise: compared as a rotation it makes an error of up to π that
    only α1 · r², with r ≈ 0, could explain (the sample's mapping passes, which turn in place: α1 fitted as 400)."""
    pure = (odo.trans < MIN_TRANS_FOR_BEARING_M) | (ref.trans < MIN_TRANS_FOR_BEARING_M)

    def fold(inc: Increments) -> Increments:
        turn = wrap_angle(inc.rot1 + inc.rot2)
        return Increments(np.where(pure, 0.0, inc.rot1), inc.trans, np.where(pure, turn, inc.rot2))

    return fold(odo), fold(ref)


def estimate_alphas(odometry: npt.ArrayLike, reference: npt.ArrayLike, min_motion_m: float = 0.02
                    ) -> OdometryAlphas:
    """α1..α4 from odometry and reference poses (N, 3) sampled at the same times.

    Increments where the robot moved less than ``min_motion_m`` and turned less than 1° carry no information
    and are skipped.
    """
    odo = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
    ref = np.asarray(reference, dtype=np.float64).reshape(-1, 3)
    io, ir = _as_pure_rotations_below_bearing_threshold(odometry_increments(odo[:, 0], odo[:, 1], odo[:, 2]),
                                                        odometry_increments(ref[:, 0], ref[:, 1], ref[:, 2]))
    moving = (ir.trans > min_motion_m) | (np.abs(ir.rot1) + np.abs(ir.rot2) > np.radians(1.0))
    r1, tr, r2 = ir.rot1[moving], ir.trans[moving], ir.rot2[moving]
    e_r1 = wrap_angle(io.rot1[moving] - r1)
    e_tr = io.trans[moving] - tr
    e_r2 = wrap_angle(io.rot2[moving] - r2)
    m1, m2 = rotation_noise_magnitude(r1), rotation_noise_magnitude(r2)
    # rotation errors: [α1, α2] from both rotations; translation errors: [α3, α4]
    a_rot = np.concatenate([np.stack([m1**2, tr**2], 1), np.stack([m2**2, tr**2], 1)])
    b_rot = np.concatenate([e_r1**2, e_r2**2])
    a_tr = np.stack([tr**2, m1**2 + m2**2], 1)
    alpha12, _ = nnls(a_rot, b_rot) if b_rot.size else (np.zeros(2), 0.0)
    alpha34, _ = nnls(a_tr, e_tr**2) if e_tr.size else (np.zeros(2), 0.0)
    return OdometryAlphas(float(alpha12[0]), float(alpha12[1]), float(alpha34[0]), float(alpha34[1]),
                          int(moving.sum()))


@dataclass(frozen=True)
class OmniOdometryAlphas:
    """Fitted α1..α5 of Nav2 AMCL's omnidirectional model and the number of increments used."""

    alpha1: float
    alpha2: float
    alpha3: float
    alpha4: float
    alpha5: float
    increments: int


def estimate_omni_alphas(odometry: npt.ArrayLike, reference: npt.ArrayLike, min_motion_m: float = 0.02
                         ) -> OmniOdometryAlphas:
    """α1..α5 of the omnidirectional model (:func:`~.motion_model.sample_motion_model_omni`) from odometry and
    reference poses (N, 3) sampled at the same times.

    Each increment is taken in the robot's frame at its start: the odometry's moves δtrans along the bearing β
    and turns δrot. The reference's increment minus the odometry's is split into an error along β (variance α3
    δtrans² + α4 δrot²), across it (the strafe, α4 δrot² + α5 δtrans²) and in heading (α1 δrot² + α2 δtrans²).
    The squared errors are non-negative least-squares fits of those variances: heading alone (rad²) for α1, α2,
    along and across together (m²) for α3, α4, α5. Increments where the robot moved less than ``min_motion_m``
    and turned less than 1° are skipped.
    """
    odo = relative(*_consecutive(odometry))
    ref = relative(*_consecutive(reference))
    tr = np.hypot(odo[:, 0], odo[:, 1])
    rot = wrap_angle(odo[:, 2])
    moving = (np.hypot(ref[:, 0], ref[:, 1]) > min_motion_m) | (np.abs(wrap_angle(ref[:, 2])) > np.radians(1.0))
    tr, rot, odo, ref = tr[moving], rot[moving], odo[moving], ref[moving]
    bearing = np.arctan2(odo[:, 1], odo[:, 0])
    dx, dy = ref[:, 0] - odo[:, 0], ref[:, 1] - odo[:, 1]
    along = dx * np.cos(bearing) + dy * np.sin(bearing)
    across = dx * np.sin(bearing) - dy * np.cos(bearing)
    e_rot = wrap_angle(ref[:, 2] - odo[:, 2])
    t2, r2, zero = tr**2, rot**2, np.zeros_like(tr)
    alpha12, _ = nnls(np.stack([r2, t2], 1), e_rot**2) if tr.size else (np.zeros(2), 0.0)
    a_xy = np.concatenate([np.stack([t2, r2, zero], 1), np.stack([zero, r2, t2], 1)])
    alpha345, _ = nnls(a_xy, np.concatenate([along**2, across**2])) if tr.size else (np.zeros(3), 0.0)
    a1, a2 = (float(a) for a in alpha12)
    a3, a4, a5 = (float(a) for a in alpha345)
    return OmniOdometryAlphas(a1, a2, a3, a4, a5, int(moving.sum()))


def _consecutive(poses: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """(poses[:-1], poses[1:]) of an (N, 3) array."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return p[:-1], p[1:]
