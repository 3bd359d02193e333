"""Planar line segments stored as arrays (..., 2, 2): [[a_x, a_y], [b_x, b_y]]."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def point_segment_distance(points: FloatArray, segments: FloatArray) -> FloatArray:
    """Distances (..., S) from points (..., 2) to segments (..., S, 2, 2) (broadcast):
    |p − (a + clip(u, 0, 1)·e)| with u = (p − a)·e / |e|²."""
    a = segments[..., 0, :]
    e = segments[..., 1, :] - a
    w = points[..., None, :] - a
    ee = np.maximum(np.einsum("...i,...i->...", e, e), 1e-300)
    u = np.clip(np.einsum("...i,...i->...", w, e) / ee, 0.0, 1.0)
    diff = w - u[..., None] * e
    return np.asarray(np.hypot(diff[..., 0], diff[..., 1]), dtype=np.float64)
