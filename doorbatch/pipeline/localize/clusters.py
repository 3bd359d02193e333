"""AMCL's pose estimate: the weighted mean of the heaviest cluster of particles (``pf_cluster_stats``).

AMCL bins the particles as its KLD-sampling does, key = (⌊x / b_xy⌋, ⌊y / b_xy⌋, ⌊θ / b_θ⌋) with θ in (−π, π]
(no wrap between the first and last heading bin, as its kd-tree has none), joins bins that touch (the 26
neighbours of a bin) into clusters, and publishes the mean of the cluster with the most weight, with the whole
set's covariance. A cloud split between two hypotheses (a global start, random particles injected by recovery)
then reports one of them rather than a pose between them.
"""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from doorbatch.pipeline.localize.particles import ParticleSet, weighted_pose_mean

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

_NEIGHBOURS = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)], dtype=np.int64)


def cluster_labels(pose: npt.ArrayLike, bin_xy_m: float, bin_yaw_rad: float) -> IntArray:
    """Per particle (N, 3 poses) the index of its cluster: bins of b_xy × b_xy × b_θ joined through their 26
    neighbours (AMCL's ``pf_cluster_stats`` over its kd-tree)."""
    p = np.asarray(pose, dtype=np.float64)
    keys = np.floor(np.column_stack([p[:, 0] / bin_xy_m, p[:, 1] / bin_xy_m, p[:, 2] / bin_yaw_rad])).astype(np.int64)
    lo = keys.min(axis=0) - 1
    size = keys.max(axis=0) - lo + 2  # one empty bin of margin on each side: neighbours never wrap
    code = ((keys[:, 0] - lo[0]) * size[1] + (keys[:, 1] - lo[1])) * size[2] + (keys[:, 2] - lo[2])
    bins, of_particle = np.unique(code, return_inverse=True)  # sorted
    rows, cols = [], []
    for d in _NEIGHBOURS:
        other = bins + (d[0] * size[1] + d[1]) * size[2] + d[2]
        at = np.minimum(np.searchsorted(bins, other), len(bins) - 1)
        found = bins[at] == other
        rows.append(np.flatnonzero(found))
        cols.append(at[found])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(r.size), (r, c)), shape=(len(bins), len(bins)))
    _, labels = connected_components(graph, directed=False)
    return np.asarray(labels, dtype=np.int64)[of_particle.reshape(-1)]


def heaviest_cluster_mean(particles: ParticleSet, bin_xy_m: float, bin_yaw_rad: float) -> FloatArray:
    """The weighted mean pose (circular mean of yaw) of the cluster holding the most weight."""
    labels = cluster_labels(particles.pose, bin_xy_m, bin_yaw_rad)
    weight = particles.weight
    mask = labels == int(np.argmax(np.bincount(labels, weights=weight)))
    return weighted_pose_mean(particles.pose[mask], weight[mask] / weight[mask].sum())
