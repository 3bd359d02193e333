"""Synthetic rooms for the MCL tests: wall segments, their rasterized map_server map, ray-cast scans."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import compose, relative
from doorbatch.io.recording import PoseSeries, Recording, ScanSet
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.likelihood_field import BeamSet, select_beams
from doorbatch.sim.raycast import cast_rays

FloatArray = npt.NDArray[np.float64]
RES = 0.05
LASER_X = 0.2  # laser 20 cm ahead of base_link
LASER_TO_BASE = np.array([[1.0, 0, 0, LASER_X], [0, 1.0, 0, 0], [0, 0, 1.0, 0.3], [0, 0, 0, 1.0]])


def polyline(*pts: tuple[float, float]) -> FloatArray:
    """Segments (S, 2, 2) joining consecutive points."""
    p = np.asarray(pts, dtype=np.float64)
    return np.stack([p[:-1], p[1:]], axis=1)


def asymmetric_room() -> FloatArray:
    """An 8 m × 5 m room (x ∈ [0, 8], y ∈ [0, 5]) with a notch, an L-shaped counter and a pillar: no symmetry."""
    outer = polyline((0, 0), (8, 0), (8, 3.5), (7, 3.5), (7, 5), (0, 5), (0, 0))
    counter = polyline((1.5, 4.2), (3.5, 4.2), (3.5, 3.6))
    pillar = polyline((5.2, 0.3), (5.7, 0.3), (5.7, 0.8), (5.2, 0.8), (5.2, 0.3))
    shelf = polyline((0.0, 1.5), (0.8, 1.5))
    return np.concatenate([outer, counter, pillar, shelf])


def rasterize(segments: FloatArray, x_range: tuple[float, float], y_range: tuple[float, float],
              margin: float = 0.5) -> OccupancyMap:
    """A map_server map: cells on segments occupied (100), inside the given box free (0), else unknown (−1).

    The grid is shifted by half a cell so that walls at multiples of RES run through cell centres: the
    occupied cells then sit on the walls instead of half a cell to one side.
    """
    origin = (x_range[0] - margin - RES / 2, y_range[0] - margin - RES / 2)
    width = round((x_range[1] - x_range[0] + 2 * margin) / RES)
    height = round((y_range[1] - y_range[0] + 2 * margin) / RES)
    occ = np.full((height, width), -1, dtype=np.int8)
    probe = OccupancyMap(occ, RES, *origin)
    centers = probe.cell_to_world(np.stack(np.meshgrid(np.arange(height), np.arange(width), indexing="ij"), -1))
    inside = ((centers[..., 0] > x_range[0]) & (centers[..., 0] < x_range[1]) & (centers[..., 1] > y_range[0])
              & (centers[..., 1] < y_range[1]))
    occ[inside] = 0
    for a, b in segments:
        n = int(np.ceil(np.hypot(*(b - a)) / (RES / 4))) + 1
        pts = a + np.linspace(0.0, 1.0, n)[:, None] * (b - a)
        ij = probe.world_to_cell(pts)
        ok = probe.contains(ij)
        occ[ij[ok, 0], ij[ok, 1]] = 100
    return OccupancyMap(occ, RES, *origin)


def room_map() -> OccupancyMap:
    """The rasterized asymmetric room."""
    return rasterize(asymmetric_room(), (0.0, 8.0), (0.0, 5.0))


def scan_ranges(segments: FloatArray, pose: FloatArray, n_beams: int = 181, max_range: float = 12.0,
                noise_m: float = 0.0, rng: np.random.Generator | None = None) -> tuple[FloatArray, FloatArray]:
    """Ranges (beyond max_range → +inf) and angles of a 360° scan from the laser at ``pose``."""
    angles = np.linspace(-np.pi, np.pi, n_beams, endpoint=False)
    c, s = np.cos(pose[2]), np.sin(pose[2])
    origin = pose[:2] + LASER_X * np.array([c, s])
    dirs = np.stack([np.cos(angles + pose[2]), np.sin(angles + pose[2])], axis=1)
    r, _ = cast_rays(origin, dirs, segments)
    if noise_m > 0.0 and rng is not None:
        r = r + noise_m * rng.standard_normal(r.shape)
    r = np.where(r < max_range, r, np.inf)
    return r, angles


def scan_beams(segments: FloatArray, pose: FloatArray, max_beams: int = 60, max_range: float = 12.0,
               noise_m: float = 0.0, rng: np.random.Generator | None = None) -> BeamSet:
    """The beams the endpoint model uses for a scan from ``pose``."""
    r, a = scan_ranges(segments, pose, max_range=max_range, noise_m=noise_m, rng=rng)
    return select_beams(r, a, 0.05, max_range, LASER_TO_BASE, max_beams)


def loop_trajectory(n: int) -> FloatArray:
    """Poses (n, 3) around a loop in the room's open part, 5 cm apart, heading along the path."""
    t = np.linspace(0.0, 2 * np.pi, n)
    x = 4.2 + 2.6 * np.cos(t)
    y = 2.2 + 1.0 * np.sin(t)
    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    return np.stack([x, y, yaw], axis=1)


def axis_scaled_odometry(truth: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Odometry (N, 3) from ``truth``'s robot-frame steps, 3 % long along x and 3 % short along y, with white
    noise (3 mm, 4 mrad): a holonomic base's drift, starting at the origin."""
    steps = relative(truth[:-1], truth[1:])
    noisy = steps * [1.03, 0.97, 1.0] + rng.normal(0.0, [0.003, 0.003, 0.004], steps.shape)
    odom = np.zeros_like(truth)
    for k, step in enumerate(noisy, start=1):
        odom[k] = compose(odom[k - 1], step)
    return odom


def room_recording(truth: FloatArray, odom: FloatArray, rng: np.random.Generator,
                   reference: FloatArray | None = None, period_ns: int = 100_000_000,
                   segments: FloatArray | None = None, max_range: float = 12.0) -> Recording:
    """A log in the room (or among ``segments``) as a recording: 360° scans (up to ``max_range``) ray cast from
    ``truth`` (1 cm noise) every ``period_ns``, the ``odom`` poses as odometry and, if given, ``reference`` as its
    reference pose topic."""
    walls = asymmetric_room() if segments is None else segments
    ranges, angles = zip(*(scan_ranges(walls, pose, max_range=max_range, noise_m=0.01, rng=rng) for pose in truth),
                         strict=True)
    n = len(truth)
    stamps = np.arange(n, dtype=np.int64) * period_ns
    scans = ScanSet(stamps, [r.astype(np.float32) for r in ranges], np.full(n, angles[0][0]),
                    np.full(n, angles[0][1] - angles[0][0]), np.full(n, 0.05), np.full(n, 12.0),
                    np.broadcast_to(np.array([[1.0, 0.0, LASER_X], [0.0, 1.0, 0.0]]), (n, 2, 3)).copy(), "laser")
    ref = None if reference is None else PoseSeries(stamps, reference, "map")
    return Recording("room.mcap", scans, PoseSeries(stamps, odom, "odom"), ref)
