"""Synthetic worlds, scans and drifting odometry for the scan-matching tests (seeded, known geometry)."""

from __future__ import annotations

import itertools

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import compose, relative
from doorbatch.sim.raycast import cast_rays

FloatArray = npt.NDArray[np.float64]


def polyline(points: list[tuple[float, float]]) -> FloatArray:
    """Segments (S, 2, 2) joining consecutive points."""
    p = np.asarray(points, dtype=np.float64)
    return np.stack([p[:-1], p[1:]], axis=1)


def room_segments() -> FloatArray:
    """An asymmetric 8 m × 5 m room with a recess, a doorway jamb and a box: well constrained in x, y, yaw."""
    outer = polyline([(0, 0), (8, 0), (8, 2), (8.6, 2), (8.6, 3.2), (8, 3.2), (8, 5), (3, 5), (3, 4.4),
                      (2.6, 4.4), (2.6, 5), (0, 5), (0, 0)])
    box = polyline([(5, 1.5), (5.8, 1.5), (5.8, 2.1), (5, 2.1), (5, 1.5)])
    return np.concatenate([outer, box])


def _wall_with_niches(y: float, side: float, niches: list[tuple[float, float, float]], x0: float, x1: float
                      ) -> list[tuple[float, float]]:
    """Points of a wall along x at height y with rectangular niches (start, end, depth) opening away (side)."""
    pts = [(x0, y)]
    for a, b, depth in niches:
        pts += [(a, y), (a, y + side * depth), (b, y + side * depth), (b, y)]
    return [*pts, (x1, y)]


def corridor_segments() -> FloatArray:
    """A 26 m × 2 m corridor with irregular niches on both sides and closed ends (asymmetric)."""
    top = _wall_with_niches(1.0, 1.0, [(2, 3, 0.5), (6.5, 7.3, 0.4), (11, 12.2, 0.6), (15.5, 16.3, 0.5),
                                       (20, 21, 0.4)], -1.0, 25.0)
    bottom = _wall_with_niches(-1.0, -1.0, [(4, 5, 0.5), (9, 9.8, 0.3), (13.5, 14.7, 0.6), (18, 18.8, 0.4),
                                            (22.5, 23.5, 0.5)], -1.0, 25.0)
    ends = polyline([(-1, -1), (-1, 1)]), polyline([(25, -1), (25, 1)])
    return np.concatenate([polyline(top), polyline(bottom), *ends])


def simulate_scan(segments: FloatArray, pose: FloatArray, rng: np.random.Generator, *, beams: int = 360,
                  max_range_m: float = 10.0, noise_m: float = 0.01) -> FloatArray:
    """Hit points (N, 2) in the sensor frame of a 360° scan from ``pose``, Gaussian range noise."""
    angles = np.linspace(-np.pi, np.pi, beams, endpoint=False)
    world = angles + pose[2]
    ranges, _ = cast_rays(pose[:2], np.stack([np.cos(world), np.sin(world)], axis=1), segments)
    ranges = ranges + rng.normal(0.0, noise_m, beams)
    hit = np.isfinite(ranges) & (ranges < max_range_m)
    return np.stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])], axis=1)


def corridor_truth(n: int = 200, step_m: float = 0.1) -> FloatArray:
    """Poses (n, 3) weaving gently along the corridor centre line from x = 0.5."""
    x = 0.5 + step_m * np.arange(n)
    y = 0.25 * np.sin(x / 2.5)
    yaw = np.arctan2(0.25 / 2.5 * np.cos(x / 2.5), 1.0)
    return np.stack([x, y, yaw], axis=1)


def drifting_odometry(truth: FloatArray, rng: np.random.Generator, *, scale: float = 1.03,
                      yaw_bias_rad_per_m: float = np.deg2rad(0.6), noise_m: float = 0.005,
                      noise_rad: float = np.deg2rad(0.2), jumps: dict[int, tuple[float, float, float]] | None = None
                      ) -> FloatArray:
    """Odometry integrated from the true increments with a scale error, a yaw bias per metre, white noise,
    and optional jumps (dx, dy, dyaw) added to the increment into the given scan indices."""
    inc = relative(truth[:-1], truth[1:])
    dist = np.hypot(inc[:, 0], inc[:, 1])
    inc[:, :2] = inc[:, :2] * scale + rng.normal(0.0, noise_m, (len(inc), 2))
    inc[:, 2] += yaw_bias_rad_per_m * dist + rng.normal(0.0, noise_rad, len(inc))
    for k, jump in (jumps or {}).items():
        inc[k - 1] += np.asarray(jump)
    odom = np.empty_like(truth)
    odom[0] = truth[0]
    for k in range(1, len(truth)):
        odom[k] = compose(odom[k - 1], inc[k - 1])
    return odom


def ate_rmse_m(estimate: FloatArray, truth: FloatArray) -> float:
    """Translation RMSE with no alignment (both trajectories start at the same pose)."""
    return float(np.sqrt(np.mean(np.sum((estimate[:, :2] - truth[:, :2]) ** 2, axis=1))))


def ring_segments() -> FloatArray:
    """A 2 m wide corridor around an 18 m × 10 m block (outer walls 18 × 10 m, inner block 14 × 6 m), its
    south side plain and straight, the other three sides and the corners with irregular niches (asymmetric)."""
    outer = polyline([(-1, -1), (17, -1), (17, 2), (17.5, 2), (17.5, 3.5), (17, 3.5), (17, 9), (12, 9), (12, 9.6),
                      (10.8, 9.6), (10.8, 9), (5, 9), (5, 9.4), (4.2, 9.4), (4.2, 9), (-1, 9), (-1, 6), (-1.6, 6),
                      (-1.6, 4.9), (-1, 4.9), (-1, -1)])
    inner = polyline([(1, 1), (15, 1), (15, 5.5), (14.6, 5.5), (14.6, 6.2), (15, 6.2), (15, 7), (8, 7),
                      (8, 6.5), (7.2, 6.5), (7.2, 7), (1, 7), (1, 3.2), (1.5, 3.2), (1.5, 2.4), (1, 2.4), (1, 1)])
    return np.concatenate([outer, inner])


def ring_truth(step_m: float = 0.2, extra_m: float = 4.0) -> FloatArray:
    """Poses once around the ring's centre line (0, 0) → (16, 0) → (16, 8) → (0, 8) → (0, 0), turning in place
    at the corners in 22.5° steps, then ``extra_m`` along the south side again."""
    corners = [(0.0, 0.0), (16.0, 0.0), (16.0, 8.0), (0.0, 8.0), (0.0, 0.0), (extra_m, 0.0)]
    poses: list[tuple[float, float, float]] = []
    for (x0, y0), (x1, y1) in itertools.pairwise(corners):
        yaw = float(np.arctan2(y1 - y0, x1 - x0))
        if poses:  # turn in place from the previous heading
            start = poses[-1][2]
            turn = float(np.angle(np.exp(1j * (yaw - start))))
            poses += [(x0, y0, start + turn * k / 4) for k in range(1, 4)]
        n = round(np.hypot(x1 - x0, y1 - y0) / step_m)
        poses += [(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n, yaw) for k in range(n)]
    poses.append((corners[-1][0], corners[-1][1], 0.0))
    out = np.asarray(poses)
    out[:, 2] = np.angle(np.exp(1j * out[:, 2]))
    return out
