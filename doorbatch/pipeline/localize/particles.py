"""The particle state shared by MCL and the RBPF (arrays over N particles, D doors).

Poses are float64 (x, y, yaw in the map frame); weights are normalized (sum 1). The RBPF adds per particle
and door a Gaussian opening angle (mean, variance) relative to the door's closed direction, CCW positive
(paper 000, Sec. IV: one Kalman filter per door per particle). MCL leaves the door arrays (N, 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def weighted_pose_mean(pose: FloatArray, weight: FloatArray) -> FloatArray:
    """Σ w·(x, y) and the circular mean of the yaw, atan2(Σ w sin θ, Σ w cos θ), of (N, 3) poses; ``weight``
    sums to 1."""
    return np.array([weight @ pose[:, 0], weight @ pose[:, 1],
                     np.arctan2(weight @ np.sin(pose[:, 2]), weight @ np.cos(pose[:, 2]))])


@dataclass
class ParticleSet:
    """N particles: pose (N, 3), weight (N,), door angle mean and variance (N, D)."""

    pose: FloatArray
    weight: FloatArray
    door_mean: FloatArray
    door_var: FloatArray

    @classmethod
    def gaussian(cls, mean: npt.ArrayLike, sigma: npt.ArrayLike, n: int, rng: np.random.Generator,
                 door_mean: npt.ArrayLike = (), door_var: npt.ArrayLike = ()) -> ParticleSet:
        """n particles drawn around a pose with per-axis standard deviations, equal weights."""
        pose = np.asarray(mean, dtype=np.float64) + rng.standard_normal((n, 3)) * np.asarray(sigma, dtype=np.float64)
        pose[:, 2] = np.arctan2(np.sin(pose[:, 2]), np.cos(pose[:, 2]))
        dm = np.broadcast_to(np.asarray(door_mean, dtype=np.float64), (n, len(np.atleast_1d(door_mean)))).copy()
        dv = np.broadcast_to(np.asarray(door_var, dtype=np.float64), (n, len(np.atleast_1d(door_var)))).copy()
        return cls(pose, np.full(n, 1.0 / n), dm, dv)

    def __len__(self) -> int:
        return int(self.pose.shape[0])

    @property
    def n_doors(self) -> int:
        """D."""
        return int(self.door_mean.shape[1])

    def take(self, index: npt.NDArray[np.intp]) -> ParticleSet:
        """The particles at ``index`` (resampling), with equal weights."""
        n = index.shape[0]
        return ParticleSet(self.pose[index].copy(), np.full(n, 1.0 / n), self.door_mean[index].copy(),
                           self.door_var[index].copy())

    def neff(self) -> float:
        """Effective sample size 1 / Σ w²."""
        return float(1.0 / np.sum(self.weight**2))

    def mean_and_covariance(self) -> tuple[FloatArray, FloatArray]:
        """Weighted mean pose (circular mean of yaw) and 3×3 covariance (yaw residuals wrapped)."""
        w = self.weight
        mean = weighted_pose_mean(self.pose, w)
        d = self.pose - mean
        d[:, 2] = np.arctan2(np.sin(d[:, 2]), np.cos(d[:, 2]))
        cov = (d * w[:, None]).T @ d
        return mean, cov

    def door_estimate(self) -> tuple[FloatArray, FloatArray]:
        """Per door: weighted mean angle and its standard deviation (mixture of the particles' Gaussians)."""
        w = self.weight[:, None]
        mean = np.sum(w * self.door_mean, axis=0)
        var = np.sum(w * (self.door_var + (self.door_mean - mean) ** 2), axis=0)
        return mean, np.sqrt(var)
