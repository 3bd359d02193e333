"""How much a pose series jitters from pose to pose: the white noise of a reference pose topic.

A simulator's ground truth with noise added per message (Gazebo's p3d plugin with ``gaussianNoise``), or a
localizer's output that jumps by its corrections, puts each scan drawn at its pose a little off: a map built from
it is blurred by about σ_θ·range + σ_xy. The jitter is told apart from the robot's own motion in two ways, each
a robust (median absolute deviation) standard deviation per component:

(a) against the odometry over the same steps: the reference's increments between consecutive poses (in the body
    frame) minus the odometry's, interpolated at the same stamps. Wheel odometry drifts slowly, so white noise σ
    on the reference leaves increments that differ by σ√2;
(b) the reference alone: the change of its body-frame increment from one step to the next. A robot's motion
    changes it by acceleration · dt², white noise σ by σ√6.

(a) also holds the odometry's own jitter (a simulator's white odometry noise), (b) the real accelerations between
sparse poses; the noise of the reference is at most either, so the estimate is the smaller of the two.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import relative

FloatArray = npt.NDArray[np.float64]
MAD_TO_STD = 1.4826  # σ of a normal distribution per median absolute deviation


@dataclass(frozen=True)
class PoseJitter:
    """Estimated white noise of a pose series: position (the larger of the x and y components) and heading."""

    xy_m: float
    yaw_rad: float


def _robust_std(values: FloatArray) -> FloatArray:
    """Per column, the median absolute deviation scaled to a normal σ."""
    return MAD_TO_STD * np.median(np.abs(values - np.median(values, axis=0)), axis=0)


def pose_jitter(poses: npt.ArrayLike, odometry: npt.ArrayLike | None = None) -> PoseJitter:
    """The white noise of ``poses`` (K, 3) from pose to pose (module docstring); ``odometry`` (K, 3): the odometry
    at the same stamps, when there is one. NaN for fewer than four poses."""
    p = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    if len(p) < 4:
        return PoseJitter(math.nan, math.nan)
    inc = relative(p[:-1], p[1:])  # body-frame increments, headings wrapped
    change = np.diff(inc, axis=0)
    change[:, 2] = wrap_angle(change[:, 2])
    sigma = _robust_std(change) / math.sqrt(6.0)  # (b)
    if odometry is not None:
        odo = np.asarray(odometry, dtype=np.float64).reshape(-1, 3)
        diff = inc - relative(odo[:-1], odo[1:])
        diff[:, 2] = wrap_angle(diff[:, 2])
        sigma = np.minimum(sigma, _robust_std(diff) / math.sqrt(2.0))  # (a)
    return PoseJitter(float(max(sigma[0], sigma[1])), float(sigma[2]))
