"""Wall proposals of paper 001 Sec. VI: a Hough transform of all points, analysed for the dominant line
orientations; lines are proposed at those orientations, strongest first."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

_MAX_POINTS = 60000  # points voted (an even subsample of more): the peaks do not need every point


def hough_lines(points: FloatArray, step_deg: float, bin_m: float, orientation_share: float, min_votes: int,
                max_lines: int) -> list[tuple[FloatArray, float, int]]:
    """Lines (normal n, offset β, votes) with n = (cos θ, sin θ), β = ρ: the accumulator A[θ, ρ] of
    ρ = x cos θ + y sin θ; dominant orientations are the θ whose peakedness Σ_ρ A² is a local maximum
    with at least ``orientation_share`` of the largest, and the perpendicular of the largest; at those θ
    (± one step) every local maximum in ρ with ≥ ``min_votes`` is a proposal, most votes first."""
    if points.shape[0] < min_votes:
        return []
    stride = max(1, points.shape[0] // _MAX_POINTS)
    pts = points[::stride]
    scale = stride
    thetas = np.deg2rad(np.arange(0.0, 180.0, step_deg))
    rho = pts @ np.stack([np.cos(thetas), np.sin(thetas)])  # (P, A)
    lo = float(rho.min())
    bins = np.floor((rho - lo) / bin_m).astype(np.int64)
    n_bins = int(bins.max()) + 1
    acc = np.zeros((thetas.shape[0], n_bins))
    for a in range(thetas.shape[0]):
        acc[a] = np.bincount(bins[:, a], minlength=n_bins) * scale
    peaked = np.sum(acc * acc, axis=1)
    prev, nxt = np.roll(peaked, 1), np.roll(peaked, -1)
    dominant = np.flatnonzero((peaked >= prev) & (peaked >= nxt) & (peaked >= orientation_share * peaked.max()))
    # the perpendicular of the strongest orientation too: buildings are mostly rectangular, and a corridor's
    # short end walls would otherwise fall under the share of its long side walls
    best = int(np.argmax(peaked))
    dominant = np.union1d(dominant, [(best + thetas.shape[0] // 2) % thetas.shape[0]])
    found: dict[tuple[int, int], int] = {}
    for a0 in dominant.tolist():
        for a_raw in (a0 - 1, a0, a0 + 1):
            a = a_raw % thetas.shape[0]
            row = acc[a]
            left = np.concatenate([[-1.0], row[:-1]])
            right = np.concatenate([row[1:], [-1.0]])
            peaks = np.flatnonzero((row >= left) & (row > right) & (row >= min_votes))
            for p in peaks.tolist():
                found[(a, p)] = int(row[p])
    ranked = sorted(found.items(), key=lambda kv: -kv[1])[:max_lines]
    out: list[tuple[FloatArray, float, int]] = []
    for (ai, pi), votes in ranked:
        th = thetas[ai]
        out.append((np.array([np.cos(th), np.sin(th)]), float(lo + (pi + 0.5) * bin_m), votes))
    return out
