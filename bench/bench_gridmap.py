"""Grid stage speed: scans/s of occupancy grid integration (360-beam scans, 0.05 m cells) and the overhead that
door detection (paper 000, Sec. III) adds on top.

Run: ``taskset -c 0 python bench/bench_gridmap.py [--scans N] [--repeats R] [--logs LOG ...]``. The scans are
simulated once
(not timed): a 40 m corridor with 16 rooms, doors closed in pass 1 and half of them open 60° in pass 2, a
person walking against the robot in pass 2. Both timings end with the occupancy map output; each figure is
the best of R repeats (grid-only and full runs interleaved), in CPU time of the process (the machine is
shared: wall time also counts the waits for the core). The NumPy reference of the integration kernel is
timed once, for comparison. With ``--logs``, the passes are those logs instead (each log one pass, reference
poses, read before timing), e.g. the sample's mapping run: more dynamic points per scan than the simulated
corridor (a person in view most of the time, 720 beams).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, GridConfig
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.gridmap.build import GridMapper, MapScan
from doorbatch.pipeline.gridmap.occupancy import (
    LogOddsGrid,
    integrate_scan,
    integrate_scan_numpy,
    new_grid,
    to_occupancy_map,
)
from doorbatch.pipeline.mapping import map_scans, pass_poses

FloatArray = npt.NDArray[np.float64]
Integrate = Callable[..., LogOddsGrid]


def cast(origin: FloatArray, dirs: FloatArray, segs: FloatArray) -> FloatArray:
    """First-hit range of each ray among segments (+inf on a miss)."""
    a, e = segs[:, 0], segs[:, 1] - segs[:, 0]
    w = a - origin
    den = dirs[:, None, 0] * e[None, :, 1] - dirs[:, None, 1] * e[None, :, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0])[None] / den
        u = (w[None, :, 0] * dirs[:, None, 1] - w[None, :, 1] * dirs[:, None, 0]) / den
    return np.asarray(np.where((t > 1e-9) & (u >= 0) & (u <= 1), t, np.inf).min(axis=1), dtype=np.float64)


def world(open_angle: float, person: FloatArray | None) -> FloatArray:
    """Corridor y ∈ [0, 2.4], x ∈ [0, 40]; rooms of 4 × 4 m on both sides with 0.9 m doors."""
    segs: list[list[tuple[float, float]]] = [[(0, 0), (0, 2.4)], [(40, 0), (40, 2.4)]]
    for y, side in ((0.0, -1.0), (2.4, 1.0)):
        xs = [0.0]
        for i in range(8):
            x0 = 1 + 5 * i
            xs += [x0 + 1.5, x0 + 2.4]
            far = y + 4 * side
            segs += [[(x0, far), (x0 + 4, far)], [(x0, y), (x0, far)], [(x0 + 4, y), (x0 + 4, far)]]
            alpha = open_angle if i % 2 == 0 else 0.0
            segs.append([(x0 + 1.5, y), (x0 + 1.5 + 0.9 * math.cos(alpha), y + side * 0.9 * math.sin(alpha))])
        xs.append(40.0)
        segs += [[(a, y), (b, y)] for a, b in zip(xs[::2], xs[1::2], strict=True)]
    out = np.asarray(segs, dtype=np.float64)
    if person is not None:
        c = np.array([[-0.15, -0.15], [0.15, -0.15], [0.15, 0.15], [-0.15, 0.15]]) + person
        out = np.concatenate([out, np.stack([c, np.roll(c, -1, axis=0)], axis=1)])
    return out


def simulate(n_scans: int, beams: int = 360, max_range: float = 20.0, seed: int = 0) -> list[list[MapScan]]:
    """Two passes of n_scans / 2 scans each along the corridor."""
    rng = np.random.default_rng(seed)
    angles = np.linspace(-math.pi, math.pi, beams, endpoint=False)
    passes = []
    for p in range(2):
        scans = []
        m = n_scans // 2
        for k in range(m):
            f = k / max(1, m - 1)
            x = 0.5 + 39.0 * (f if p == 0 else 1 - f)
            person = np.array([39.0 - 38.0 * f, 0.9]) if p == 1 else None
            segs = world(math.radians(60.0) if p == 1 else 0.0, person)
            origin = np.array([x, 1.4 + 0.2 * math.sin(k / 15)])
            yaw = 0.05 * math.sin(k / 25)
            dirs = np.stack([np.cos(angles + yaw), np.sin(angles + yaw)], axis=1)
            r = cast(origin, dirs, segs) + rng.normal(0.0, 0.01, beams)
            hit = r < max_range
            scans.append(MapScan(origin, origin + r[hit, None] * dirs[hit], dirs[~hit]))
        passes.append(scans)
    return passes


def read_passes(logs: list[str], config: DoorbatchConfig) -> list[list[MapScan]]:
    """Each log as one pass of scans in the map frame, from its reference poses."""
    passes = []
    for log in logs:
        rec = load_recording(log, config)
        passes.append([scan._replace(points=np.ascontiguousarray(scan.points))
                       for scan in map_scans(rec, pass_poses(rec, "reference", config), config.mapping.scan_stride,
                                             config.grid.dropout_max_beams)])
    return passes


def time_grid(passes: list[list[MapScan]], config: GridConfig, integrate: Integrate = integrate_scan) -> float:
    """Seconds to integrate every scan and output the map, without door detection."""
    grid = new_grid(config, passes[0][0].origin)
    start = time.process_time()
    for scans in passes:
        for origin, points, dirs, range_max_m in scans:
            grid = integrate(grid, origin, points, dirs, config, None, range_max_m)
    to_occupancy_map(grid)
    return time.process_time() - start


def time_full(passes: list[list[MapScan]], config: GridConfig) -> tuple[float, float, int]:
    """Seconds for the whole grid stage: per scan (classification, integration, leaves; set 2 per pass),
    and once at the end (doors from the leaves, leaf removal, the map); and the number of doors."""
    mapper = GridMapper(config)
    start = time.process_time()
    for scans in passes:
        for scan in scans:
            mapper.add_scan(*scan)
        mapper.end_pass()
    middle = time.process_time()
    result = mapper.finish()
    return middle - start, time.process_time() - middle, len(result.doors)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scans", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--logs", nargs="+", help="time these logs (one pass each, reference poses) instead")
    args = parser.parse_args()
    passes = read_passes(args.logs, DoorbatchConfig()) if args.logs else simulate(args.scans)
    config = GridConfig()
    n = sum(len(p) for p in passes)
    ranges = np.concatenate([np.hypot(*(s.points - s.origin).T) for p in passes for s in p])
    time_grid(passes[:1], config)  # compile (or load) the kernels
    grid_runs, full_runs = [], []
    for _ in range(args.repeats):  # interleaved, best of each: the figures see the same machine load
        grid_runs.append(time_grid(passes, config))
        full_runs.append(time_full(passes, config))
    grid_s = min(grid_runs)
    scan_s = min(f[0] for f in full_runs)
    end_s = min(f[1] for f in full_runs)
    numpy_s = time_grid(passes, config, integrate_scan_numpy)
    source = f"{len(passes)} logs" if args.logs else "simulated, a person walks through all of pass 2"
    print(f"scans: {n}, mean {np.mean([len(s.points) for p in passes for s in p]):.0f} hits/scan, resolution "
          f"{config.resolution_m} m, mean hit range {ranges.mean():.2f} m; {source}")
    print(f"grid integration: {n / grid_s:,.0f} scans/s ({1e6 * grid_s / n:.0f} us/scan; NumPy reference "
          f"{n / numpy_s:,.0f} scans/s)")
    print(f"with door detection: {n / scan_s:,.0f} scans/s ({1e6 * scan_s / n:.0f} us/scan), "
          f"per-scan overhead {100 * (scan_s - grid_s) / grid_s:.0f}%; once per run {1e3 * end_s:.0f} ms "
          f"(total overhead {100 * (scan_s + end_s - grid_s) / grid_s:.0f}%); doors found: {full_runs[0][2]}")


if __name__ == "__main__":
    main()
