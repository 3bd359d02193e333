"""Resampling: low-variance sampling, KLD-adaptive sample size, random-particle recovery (Nav2 AMCL's pf.c).

References: Thrun, Burgard, Fox, Probabilistic Robotics, Table 4.4 (low-variance sampler) and Table 8.3
(Augmented MCL); Fox, "Adapting the sample size in particle filters through KLD-sampling", IJRR 2003;
nav2_amcl ``src/pf/pf.c`` (``pf_update_sensor``, ``pf_update_resample``, ``pf_resample_limit``) and
``src/pf/pf_kdtree.c`` (bins), ros-navigation/navigation2.

KLD bound (``pf_resample_limit``, Wilson–Hilferty approximation of the χ² quantile): with k occupied bins,

    n(k) = ⌈ (k − 1) / (2 ε) · (1 − 2/(9(k − 1)) + √(2/(9(k − 1))) · z)³ ⌉,  clamped to [min, max],

and, as in AMCL, k ≤ 1 gives ``max_particles`` (Fox's formula would give 0 → min). ε is Nav2 ``pf_err`` and
z is Nav2 ``pf_z`` used *as the quantile itself*: AMCL sets ``pf->pop_z = pf_z`` (the comment in ``pf_alloc``
calls it "the upper standard normal quantile for (1 − p)"), so Nav2's default pf_z = 0.99 means z = 0.99,
not Φ⁻¹(0.99) = 2.33. Bins are floor(x / 0.5 m), floor(y / 0.5 m), floor(yaw / 10°) (yaw not wrapped),
as AMCL's kd-tree keys.

AMCL draws samples one at a time (multinomial: "Can't (easily) combine low-variance sampler with KLD
adaptive sampling") and stops as soon as the count exceeds n(k) of the bins occupied so far. Here the same
stopping rule runs vectorized on a low-variance draw: ``max_particles`` candidates are drawn with the
low-variance sampler and put in random order (so that every prefix is a fair subsample of the stratified
draw), the number of distinct bins along that order is a cumulative sum, and the draw is cut at the first
prefix of m samples with m > n(k_m) (AMCL's test), else at ``max_particles``.

Recovery (``pf_update_sensor`` / ``pf_update_resample``): after each weighting, w_avg = Σᵢ wᵢ·pᵢ (normalized
prior weights times this scan's likelihoods: the mean likelihood of Probabilistic Robotics Table 8.3; AMCL
divides it once more by the particle count, an artefact when KLD changes the count, left out here — see
:func:`doorbatch.pipeline.localize.mcl.apply_log_likelihood`) updates w_slow += α_slow (w_avg − w_slow) and
w_fast += α_fast (w_avg − w_fast) (each initialized to the first w_avg); each resampled particle is replaced
by a uniform free-space pose with probability max(0, 1 − w_fast / w_slow); after such a resampling both
averages are reset. They are kept here as logarithms, so that likelihoods far below the float range (the
product combination) still work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.localize.likelihood_field import FreeCells

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def low_variance_resample(weights: npt.ArrayLike, n_out: int, rng: np.random.Generator) -> IntArray:
    """Indices of ``n_out`` particles by low-variance (systematic) sampling, in increasing order.

    One random offset r ~ U[0, 1/n) and the n points r + m/n on the cumulative weights; particle i is taken
    ⌊n·wᵢ⌋ or ⌈n·wᵢ⌉ times (weights need not be normalized; zero-weight particles are never taken).

    Raises:
        ValueError: Weights are empty, negative, not finite, or sum to zero.
    """
    w = np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.size == 0 or not np.all(np.isfinite(w)) or np.any(w < 0.0):
        raise ValueError("weights must be a non-empty array of finite non-negative numbers")
    cum = np.cumsum(w)
    total = cum[-1]
    if not total > 0.0:
        raise ValueError("weights sum to zero")
    points = (rng.random() + np.arange(n_out, dtype=np.float64)) * (total / n_out)
    idx: IntArray = np.minimum(np.searchsorted(cum, points, side="right"), w.size - 1).astype(np.int64)
    return idx


def kld_sample_counts(k: npt.ArrayLike, pf_err: float, pf_z: float, min_particles: int, max_particles: int
                      ) -> IntArray:
    """AMCL's ``pf_resample_limit`` for each bin count in ``k`` (module docstring)."""
    kk = np.asarray(k, dtype=np.float64)
    km1 = np.maximum(kk - 1.0, 1.0)  # k ≤ 1 is replaced below
    b = 2.0 / (9.0 * km1)
    x = 1.0 - b + np.sqrt(b) * pf_z
    n = np.ceil(km1 / (2.0 * pf_err) * x * x * x)
    n = np.clip(n, min_particles, max_particles)
    return np.where(kk <= 1.0, max_particles, n).astype(np.int64)


def kld_sample_count(k: int, pf_err: float, pf_z: float, min_particles: int, max_particles: int) -> int:
    """Particles needed with ``k`` occupied bins (AMCL's ``pf_resample_limit``; k ≤ 1 → max_particles)."""
    return int(kld_sample_counts(np.array([k]), pf_err, pf_z, min_particles, max_particles)[0])


def bin_ids(pose: npt.ArrayLike, bin_xy_m: float, bin_yaw_rad: float) -> IntArray:
    """One integer per particle that is equal exactly for particles in the same (x, y, yaw) bin."""
    p = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    keys = np.floor(p / np.array([bin_xy_m, bin_xy_m, bin_yaw_rad])).astype(np.int64)
    if keys.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    if float(span[0]) * float(span[1]) * float(span[2]) < 2.0**62:
        ids: IntArray = (keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2]
        return ids
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    return inverse.reshape(-1).astype(np.int64)


def occupied_bins(pose: npt.ArrayLike, bin_xy_m: float, bin_yaw_rad: float) -> int:
    """Number of distinct (x, y, yaw) bins holding at least one particle (AMCL's kd-tree leaf count)."""
    return int(np.unique(bin_ids(pose, bin_xy_m, bin_yaw_rad)).size)


def cumulative_bins(ids: npt.ArrayLike) -> IntArray:
    """For each position m, the number of distinct ids among ids[0..m]."""
    a = np.asarray(ids).reshape(-1)
    first = np.zeros(a.shape[0], dtype=np.int64)
    if a.size:
        _, first_index = np.unique(a, return_index=True)
        first[first_index] = 1
    return np.cumsum(first)


@dataclass(frozen=True)
class RecoveryState:
    """AMCL's long- and short-term averages of the weights, as logs (−inf: not yet initialized)."""

    log_w_slow: float = -math.inf
    log_w_fast: float = -math.inf

    @property
    def w_slow(self) -> float:
        """w_slow (0 when not initialized, as AMCL)."""
        return math.exp(self.log_w_slow)

    @property
    def w_fast(self) -> float:
        """w_fast (0 when not initialized, as AMCL)."""
        return math.exp(self.log_w_fast)

    def update(self, log_w_avg: float, alpha_slow: float, alpha_fast: float) -> RecoveryState:
        """The averages after a weighting whose mean weight is exp(log_w_avg)."""
        return RecoveryState(_ema(self.log_w_slow, log_w_avg, alpha_slow), _ema(self.log_w_fast, log_w_avg, alpha_fast))

    def random_fraction(self) -> float:
        """Probability of replacing a resampled particle by a random one: max(0, 1 − w_fast / w_slow)."""
        if not (math.isfinite(self.log_w_slow) and math.isfinite(self.log_w_fast)):
            return 0.0  # AMCL: 1 − 0/0 is NaN, and drand48() < NaN never injects
        return max(0.0, 1.0 - math.exp(self.log_w_fast - self.log_w_slow))


def _ema(log_avg: float, log_new: float, alpha: float) -> float:
    """log of ((1 − α)·avg + α·new), or log_new when avg is not initialized."""
    if not math.isfinite(log_avg):
        return log_new
    if alpha <= 0.0:
        return log_avg
    if alpha >= 1.0:
        return log_new
    return float(np.logaddexp(math.log1p(-alpha) + log_avg, math.log(alpha) + log_new))


@dataclass(frozen=True)
class KldDraw:
    """The outcome of a KLD-adaptive resampling of N particles into n.

    Attributes:
        index: (n,) source particle of each new one (for random ones too, so that per-particle state such as
            the RBPF's door filters can be copied from a drawn particle or reset, as the caller prefers).
        random: (n,) True where the pose was replaced by a uniform free-space pose.
        pose: (n, 3) the new poses.
        n_bins: occupied bins among the n.
    """

    index: IntArray
    random: BoolArray
    pose: FloatArray
    n_bins: int

    def __len__(self) -> int:
        return int(self.index.shape[0])


def kld_resample(pose: npt.ArrayLike, weights: npt.ArrayLike, rng: np.random.Generator, *, min_particles: int,
                 max_particles: int, pf_err: float, pf_z: float, bin_xy_m: float, bin_yaw_rad: float,
                 random_fraction: float = 0.0, free: FreeCells | None = None) -> KldDraw:
    """KLD-adaptive low-variance resampling with random-particle injection (module docstring).

    Args:
        pose: (N, 3) current poses.
        weights: (N,) weights (need not be normalized).
        rng: random generator.
        min_particles, max_particles: Nav2 ``min_particles`` / ``max_particles`` (max below min is raised to
            min, as AMCL does).
        pf_err, pf_z: Nav2 ``pf_err`` / ``pf_z`` (z used as the quantile itself, as AMCL).
        bin_xy_m, bin_yaw_rad: KLD bin size.
        random_fraction: probability that a new particle is a uniform free-space pose.
        free: free cells to draw random poses from; required when ``random_fraction`` > 0.

    Raises:
        ValueError: ``random_fraction`` > 0 without free cells, or invalid weights.
    """
    p = np.asarray(pose, dtype=np.float64).reshape(-1, 3)
    n_max = max(int(max_particles), int(min_particles))
    candidates = low_variance_resample(weights, n_max, rng)
    candidates = candidates[rng.permutation(n_max)]
    new_pose = p[candidates]
    random = np.zeros(n_max, dtype=bool)
    if random_fraction > 0.0:
        if free is None:
            raise ValueError("random particle injection needs the map's free cells")
        random = rng.random(n_max) < random_fraction
        n_random = int(random.sum())
        if n_random:
            new_pose[random] = free.sample_poses(n_random, rng)
    k = cumulative_bins(bin_ids(new_pose, bin_xy_m, bin_yaw_rad))
    limit = kld_sample_counts(k, pf_err, pf_z, min_particles, n_max)
    over = np.arange(1, n_max + 1) > limit
    n = int(np.argmax(over)) + 1 if over.any() else n_max
    return KldDraw(candidates[:n], random[:n], new_pose[:n], int(k[n - 1]))
