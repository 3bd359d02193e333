"""Door line fits over door points in the camera's horizontal plane (paper 003, Sec. III-B).

Points are (x, z): x to the right, z forward (depth) in the optical frame. A door seen by the camera spans
its field of view across, so the line is the depth as a function of the lateral coordinate,
z = a + b·x (the paper's "ordinary least squares"; its RANSAC parameters, max trials and residual
threshold, are those of scikit-learn's RANSACRegressor over a linear regression, so residuals are |Δz|).

* ``naive``: the line through the leftmost and the rightmost point (smallest and largest x).
* ``lsq``: ordinary least squares over all points, b = cov(x, z)/var(x), a = z̄ − b·x̄.
* ``ransac`` (Fischler & Bolles 1981): ``max_trials`` lines through two random points; the one with the
  most points within ``residual_m`` (ties: smaller sum of inlier residuals) is refitted by least squares
  on its inliers.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class LineFit(StrEnum):
    """The three fits of paper 003."""

    NAIVE = "naive"
    LSQ = "lsq"
    RANSAC = "ransac"


@dataclass(frozen=True)
class DepthLine:
    """The line z = intercept_m + slope·x in the camera's (x right, z forward) plane, and its inliers."""

    intercept_m: float
    slope: float
    inliers: npt.NDArray[np.bool_]  # (N,) points the fit used


def fit_naive(xz: FloatArray) -> DepthLine | None:
    """Line through the leftmost and rightmost points; None with fewer than two distinct x."""
    i, j = int(np.argmin(xz[:, 0])), int(np.argmax(xz[:, 0]))
    dx = xz[j, 0] - xz[i, 0]
    if dx <= 0.0:
        return None
    slope = (xz[j, 1] - xz[i, 1]) / dx
    used = np.zeros(xz.shape[0], dtype=bool)
    used[[i, j]] = True
    return DepthLine(float(xz[i, 1] - slope * xz[i, 0]), float(slope), used)


def fit_lsq(xz: FloatArray, mask: npt.NDArray[np.bool_] | None = None) -> DepthLine | None:
    """Ordinary least squares z = a + b·x over the (masked) points; None if var(x) = 0 or < 2 points."""
    use = np.ones(xz.shape[0], dtype=bool) if mask is None else mask
    x, z = xz[use, 0], xz[use, 1]
    if x.size < 2:
        return None
    xm, zm = x.mean(), z.mean()
    sxx = float(np.sum((x - xm) ** 2))
    if sxx <= 0.0:
        return None
    slope = float(np.sum((x - xm) * (z - zm))) / sxx
    return DepthLine(float(zm - slope * xm), slope, use.copy())


def fit_ransac(xz: FloatArray, max_trials: int, residual_m: float, rng: np.random.Generator) -> DepthLine | None:
    """RANSAC over all trials at once: (T, N) residuals of T two-point hypotheses (module docstring)."""
    n = xz.shape[0]
    if n < 2:
        return None
    pairs = rng.integers(0, n, size=(max_trials, 2))
    a, b = xz[pairs[:, 0]], xz[pairs[:, 1]]
    dx = b[:, 0] - a[:, 0]
    ok = np.abs(dx) > 1e-9
    if not ok.any():
        return None
    a, b, dx = a[ok], b[ok], dx[ok]
    slope = (b[:, 1] - a[:, 1]) / dx
    intercept = a[:, 1] - slope * a[:, 0]
    resid = np.abs(xz[None, :, 1] - intercept[:, None] - slope[:, None] * xz[None, :, 0])
    inlier = resid <= residual_m
    count = inlier.sum(axis=1)
    spread = np.where(inlier, resid, 0.0).sum(axis=1)
    best = int(np.lexsort((spread, -count))[0])
    return fit_lsq(xz, inlier[best])


def fit_line(xz: FloatArray, method: LineFit, max_trials: int, residual_m: float,
             rng: np.random.Generator) -> DepthLine | None:
    """The fit named by ``method``; None when the points do not define a line."""
    if method is LineFit.NAIVE:
        return fit_naive(xz)
    if method is LineFit.LSQ:
        return fit_lsq(xz)
    return fit_ransac(xz, max_trials, residual_m, rng)
