"""MCL speed and memory: particle-beam evaluations per second of ``weigh``, ``mcl_step`` time, peak memory.

A 40 m × 20 m office-like map at 5 cm (walls, rooms off a corridor, random clutter) rasterized from wall
segments; 60-beam scans (Nav2 ``max_beams``) ray cast from a pose in the corridor. ``weigh`` is timed with
particles spread around the true pose (tracking) and uniformly over the free space (global localization:
lookups scattered over the whole field). ``mcl_step`` is timed with a fixed particle count
(min_particles = max_particles = N, resampling on every update) so that every stage runs: motion model,
weighting, KLD-adaptive low-variance resampling. Peak memory: tracemalloc's peak (NumPy allocations) during
one ``mcl_step`` with 50,000 particles, and the process's maximum resident set size.

Run: ``taskset -c 0 python bench/bench_mcl.py [--repeats R] [--torch-device cuda]`` (one core, as in
docs/benchmarks.md; ``--torch-device``: the likelihood field's lookups on that torch device, ``localize.backend:
torch``).
"""

from __future__ import annotations

import argparse
import platform
import resource
import time
import tracemalloc
from collections.abc import Callable
from functools import partial

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.likelihood_field import (
    BeamSet,
    DistanceField,
    build_distance_field,
    free_cells,
    select_beams,
)
from doorbatch.pipeline.localize.mcl import MclState, global_particles, initial_particles, mcl_step, weigh
from doorbatch.sim.raycast import cast_rays

FloatArray = npt.NDArray[np.float64]
RES = 0.05
SIZE = (40.0, 20.0)
TRUTH = np.array([12.3, 10.1, 0.2])
ODOM_STEP = np.array([0.3, 0.0, 0.05])  # odometry since the last update (from the origin)


def office_segments(rng: np.random.Generator) -> FloatArray:
    """Outer walls, a corridor along y = 9..11 with rooms on both sides (door gaps), and random clutter."""
    w, h = SIZE
    segs = [[(0, 0), (w, 0)], [(w, 0), (w, h)], [(w, h), (0, h)], [(0, h), (0, 0)]]
    for y in (9.0, 11.0):
        x = 0.0
        while x < w:
            door = x + rng.uniform(2.0, 5.0)
            segs.append([(x, y), (min(door, w), y)])
            x = door + 0.9
    for x in np.arange(5.0, w, 5.0):  # room dividers
        segs += [[(x, 0), (x, 9.0)], [(x, 11.0), (x, h)]]
    for _ in range(60):  # furniture
        cx, cy = rng.uniform(0.5, w - 0.5), rng.choice([rng.uniform(0.5, 8.0), rng.uniform(12.0, h - 0.5)])
        a = rng.uniform(0, np.pi)
        d = rng.uniform(0.3, 1.2) * np.array([np.cos(a), np.sin(a)])
        segs.append([(cx, cy), (cx + d[0], cy + d[1])])
    return np.asarray(segs, dtype=np.float64)


def rasterize(segments: FloatArray) -> OccupancyMap:
    """Free inside the outer walls, occupied on the segments, a 1 m unknown margin."""
    margin = 1.0
    width, height = round((SIZE[0] + 2 * margin) / RES), round((SIZE[1] + 2 * margin) / RES)
    occ = np.full((height, width), -1, dtype=np.int8)
    occ[round(margin / RES):-round(margin / RES), round(margin / RES):-round(margin / RES)] = 0
    grid = OccupancyMap(occ, RES, -margin - RES / 2, -margin - RES / 2)
    for a, b in segments:
        n = int(np.ceil(np.hypot(*(b - a)) / (RES / 4))) + 1
        ij = grid.world_to_cell(a + np.linspace(0, 1, n)[:, None] * (b - a))
        ok = grid.contains(ij)
        occ[ij[ok, 0], ij[ok, 1]] = 100
    return grid


def scan(segments: FloatArray, config: LocalizeConfig) -> BeamSet:
    """A 720-beam 360° scan from TRUTH, reduced to the model's beams (max_beams = 60 → 61 used)."""
    angles = np.linspace(-np.pi, np.pi, 720, endpoint=False)
    dirs = np.stack([np.cos(angles + TRUTH[2]), np.sin(angles + TRUTH[2])], axis=1)
    ranges, _ = cast_rays(TRUTH[:2], dirs, segments)
    ranges = np.where(ranges < 30.0, ranges, np.inf)
    return select_beams(ranges, angles, 0.05, 30.0, np.eye(4), config.max_beams)


def best_time(fn: Callable[[], object], repeats: int) -> float:
    """Best wall time of ``repeats`` calls (after one warm-up call)."""
    fn()
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return float(best)


def bench_weigh(field: DistanceField, beams: BeamSet, config: LocalizeConfig, repeats: int) -> None:
    rng = np.random.default_rng(1)
    free = free_cells(rasterize(office_segments(np.random.default_rng(0))))
    print(f"weigh ({len(beams)} beams, float32 end points, AMCL's 1 + Σ pz³):")
    for n in (1_000, 10_000, 50_000):
        for label, particles in (("tracking", initial_particles(TRUTH, config, rng, n)),
                                 ("global", global_particles(free, n, rng))):
            t = best_time(partial(weigh, particles, beams, field, config), repeats)
            print(f"  N = {n:6d} {label:8s}: {t * 1e3:8.2f} ms  {n * len(beams) / t / 1e6:6.1f} M particle-beams/s")


def bench_step(field: DistanceField, beams: BeamSet, repeats: int) -> None:
    print("mcl_step (motion + weigh + KLD low-variance resampling every update, fixed N):")
    for n in (1_000, 10_000, 50_000):
        config = LocalizeConfig(min_particles=n, max_particles=n, resample_neff_ratio=1.0)
        rng = np.random.default_rng(2)
        state = MclState(initial_particles(TRUTH, config, rng, n), odom_at_update=np.zeros(3))

        def step(s: MclState = state, c: LocalizeConfig = config, r: np.random.Generator = rng) -> object:
            return mcl_step(s, ODOM_STEP, beams, field, c, r)

        t = best_time(step, repeats)
        print(f"  N = {n:6d}: {t * 1e3:8.2f} ms per update  ({n * len(beams) / t / 1e6:5.1f} M particle-beams/s "
              f"end to end)")


def bench_memory(field: DistanceField, beams: BeamSet) -> None:
    n = 50_000
    config = LocalizeConfig(min_particles=n, max_particles=n, resample_neff_ratio=1.0)
    rng = np.random.default_rng(3)
    state = MclState(initial_particles(TRUTH, config, rng, n), odom_at_update=np.zeros(3))
    tracemalloc.start()
    mcl_step(state, ODOM_STEP, beams, field, config, rng)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"memory, N = {n}: peak traced during mcl_step {peak / 2**20:.1f} MiB; process max RSS {rss_mb:.0f} MiB "
          f"(distance field {field.padded.nbytes / 2**20:.1f} MiB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--torch-device", default=None, help="run the field lookups in torch on this device")
    args = parser.parse_args()
    print(f"backend: {'numpy' if args.torch_device is None else 'torch on ' + args.torch_device}")
    print(f"{platform.node()} {platform.processor() or platform.machine()} Python {platform.python_version()} "
          f"NumPy {np.__version__} {time.strftime('%Y-%m-%d')}")
    config = LocalizeConfig()
    segments = office_segments(np.random.default_rng(0))
    t0 = time.perf_counter()
    grid = rasterize(segments)
    field = build_distance_field(grid, config.laser_likelihood_max_dist, torch_device=args.torch_device)
    print(f"map {grid.width} × {grid.height} cells; distance field built in {time.perf_counter() - t0:.2f} s")
    beams = scan(segments, config)
    bench_weigh(field, beams, config, args.repeats)
    bench_step(field, beams, args.repeats)
    bench_memory(field, beams)


if __name__ == "__main__":
    main()
