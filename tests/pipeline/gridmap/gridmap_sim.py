"""A small simulated corridor for the grid stage tests: walls, rooms, a pillar, hinged doors, a walking person.

Scans are cast exactly against segments (vectorized over beams × segments), with seeded range noise.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.gridmap.build import MapScan

FloatArray = npt.NDArray[np.float64]


def cast(origin: FloatArray, dirs: FloatArray, segments: FloatArray) -> FloatArray:
    """Range of the first hit of each ray o + t·d among segments a→b (+inf on a miss).

    With c(v, w) = v_x w_y − v_y w_x: t = c(a − o, e) / c(d, e), u = c(a − o, d) / c(d, e), e = b − a.
    """
    a = segments[:, 0]
    e = segments[:, 1] - a
    w = a - origin
    den = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[None, :, 0] * e[None, :, 1] - w[None, :, 1] * e[None, :, 0]) / den
        u = (w[None, :, 0] * dirs[:, None, 1] - w[None, :, 1] * dirs[:, None, 0]) / den
    ok = (den != 0) & (t > 1e-9) & (u >= 0) & (u <= 1)
    return np.asarray(np.where(ok, t, np.inf).min(axis=1), dtype=np.float64)


def square(center: tuple[float, float], size: float) -> FloatArray:
    """The four sides of an axis-aligned square as (4, 2, 2) segments."""
    cx, cy = center
    h = size / 2
    c = np.array([[cx - h, cy - h], [cx + h, cy - h], [cx + h, cy + h], [cx - h, cy + h]])
    return np.stack([c, np.roll(c, -1, axis=0)], axis=1)


@dataclass(frozen=True)
class Door:
    """A hinged leaf: free end = hinge + L·(cos φ, sin φ), φ = closed_yaw + sign·α."""

    hinge: tuple[float, float]
    length: float
    closed_yaw: float
    sign: int

    def leaf(self, alpha: float) -> FloatArray:
        phi = self.closed_yaw + self.sign * alpha
        h = np.asarray(self.hinge)
        return np.stack([h, h + self.length * np.array([math.cos(phi), math.sin(phi)])])[None]


@dataclass(frozen=True)
class Corridor:
    """Corridor y ∈ [0, 3], x ∈ [0, 14]; door A at (5, 3) and door B at (10, 3) in the top wall, each with a
    3 × 3 m room behind; a 0.4 m pillar at (8, 1)."""

    door_a: Door = Door((5.0, 3.0), 0.9, 0.0, +1)
    door_b: Door = Door((10.0, 3.0), 0.8, 0.0, +1)
    pillar_center: tuple[float, float] = (8.0, 1.0)
    static: FloatArray = field(init=False)

    def __post_init__(self) -> None:
        segs = [
            [(0, 0), (14, 0)], [(0, 0), (0, 3)], [(14, 0), (14, 3)],
            [(0, 3), (5.0, 3)], [(5.9, 3), (10.0, 3)], [(10.8, 3), (14, 3)],
            [(4, 3), (4, 6)], [(7, 3), (7, 6)], [(4, 6), (7, 6)],
            [(9, 3), (9, 6)], [(12, 3), (12, 6)], [(9, 6), (12, 6)],
        ]
        static = np.concatenate([np.asarray(segs, dtype=np.float64), square(self.pillar_center, 0.4)])
        object.__setattr__(self, "static", static)


def scan_pass(world: Corridor, alpha_a: float, alpha_b: float, *, reverse: bool, seed: int, n_scans: int = 240,
              beams: int = 360, max_range: float = 10.0, sigma: float = 0.01,
              person: tuple[tuple[float, float], tuple[float, float]] | None = None) -> list[MapScan]:
    """One pass along y = 1.8 (left → right, or back), doors held at the given angles (rad).

    ``person``: start and end of a 0.3 m square walking at constant speed during the pass.
    """
    rng = np.random.default_rng(seed)
    xs = np.linspace(0.8, 13.2, n_scans)
    if reverse:
        xs = xs[::-1]
    segs = np.concatenate([world.static, world.door_a.leaf(alpha_a), world.door_b.leaf(alpha_b)])
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    scans = []
    for k, x in enumerate(xs):
        origin = np.array([x, 1.8])
        yaw = 0.02 * math.sin(k / 7.0)
        dirs = np.stack([np.cos(angles + yaw), np.sin(angles + yaw)], axis=1)
        all_segs = segs
        if person is not None:
            f = k / max(1, n_scans - 1)
            centre = (1 - f) * np.asarray(person[0]) + f * np.asarray(person[1])
            all_segs = np.concatenate([segs, square((float(centre[0]), float(centre[1])), 0.3)])
        r = cast(origin, dirs, all_segs) + rng.normal(0.0, sigma, beams)
        hit = r < max_range
        scans.append(MapScan(origin, origin + r[hit, None] * dirs[hit], dirs[~hit]))
    return scans


@dataclass(frozen=True)
class World:
    """Static segments and hinged doors; ``scan_world`` scans it with the doors at given angles."""

    static: FloatArray
    doors: tuple[Door, ...]


def two_sided_corridor(south_length: float = 0.9) -> World:
    """Corridor y ∈ [0, 3], x ∈ [0, 14], walls on cell borders (as in the simulator's worlds), a room on
    each side: door N hinged at the west end of its doorway in the top wall, opening into the north room
    (counter-clockwise from 0°); door S hinged at the east end of its doorway in the bottom wall, opening
    into the south room (counter-clockwise from 180°, the mirror image of N)."""
    n = Door((5.0, 3.0), 0.9, 0.0, +1)
    s = Door((10.0, 0.0), south_length, math.pi, +1)
    s_free = 10.0 - south_length
    segs = [
        [(0, 3), (5.0, 3)], [(5.9, 3), (14, 3)], [(0, 0), (s_free, 0)], [(10.0, 0), (14, 0)],
        [(0, 0), (0, 3)], [(14, 0), (14, 3)],
        [(3.5, 3), (3.5, 6)], [(7.5, 3), (7.5, 6)], [(3.5, 6), (7.5, 6)],
        [(8.0, 0), (8.0, -3)], [(12.0, 0), (12.0, -3)], [(8.0, -3), (12.0, -3)],
    ]
    return World(np.asarray(segs, dtype=np.float64), (n, s))


def scan_world(world: World, angles: tuple[float, ...], *, reverse: bool, seed: int, n_scans: int = 240,
               beams: int = 360, max_range: float = 10.0, sigma: float = 0.01, y: float = 1.5) -> list[MapScan]:
    """One pass along y (left → right, or back) with door k held at ``angles[k]`` (rad)."""
    rng = np.random.default_rng(seed)
    xs = np.linspace(0.8, 13.2, n_scans)
    if reverse:
        xs = xs[::-1]
    segs = np.concatenate([world.static, *(d.leaf(a) for d, a in zip(world.doors, angles, strict=True))])
    angles_b = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    scans = []
    for k, x in enumerate(xs):
        origin = np.array([x, y])
        yaw = 0.02 * math.sin(k / 7.0)
        dirs = np.stack([np.cos(angles_b + yaw), np.sin(angles_b + yaw)], axis=1)
        r = cast(origin, dirs, segs) + rng.normal(0.0, sigma, beams)
        hit = r < max_range
        scans.append(MapScan(origin, origin + r[hit, None] * dirs[hit], dirs[~hit]))
    return scans


def scan_path(world: World, path: list[tuple[float, float]], angles: tuple[float, ...], *, seed: int,
              step_m: float = 0.05, beams: int = 540, fov_rad: float = math.radians(270.0), max_range: float = 15.0,
              sigma: float = 0.01, stray_prob: float = 0.0) -> list[MapScan]:
    """Scans every ``step_m`` along a polyline, the laser facing along it, door k held at ``angles[k]`` (rad): a robot
    that turns into rooms (:func:`scan_world` drives one straight line). ``stray_prob``: that share of the beams
    returns a uniform 0.1-2 m whatever lies there (sunlight, another laser's crosstalk), behind walls too."""
    rng = np.random.default_rng(seed)
    segs = np.concatenate([world.static, *(d.leaf(a) for d, a in zip(world.doors, angles, strict=True))])
    fan = np.linspace(-fov_rad / 2, fov_rad / 2, beams)
    scans = []
    for (x0, y0), (x1, y1) in itertools.pairwise(path):
        n = max(2, int(math.hypot(x1 - x0, y1 - y0) / step_m))
        yaw = math.atan2(y1 - y0, x1 - x0)
        for t in np.linspace(0.0, 1.0, n, endpoint=False):
            origin = np.array([x0 + t * (x1 - x0), y0 + t * (y1 - y0)])
            dirs = np.stack([np.cos(fan + yaw), np.sin(fan + yaw)], axis=1)
            r = cast(origin, dirs, segs) + rng.normal(0.0, sigma, beams)
            stray = rng.random(beams) < stray_prob
            r[stray] = rng.uniform(0.1, 2.0, int(stray.sum()))
            hit = r < max_range
            scans.append(MapScan(origin, origin + r[hit, None] * dirs[hit], dirs[~hit]))
    return scans
