"""The whole RBPF update (``rbpf_step``: motion, door random walk, static field + door likelihood with beam
skipping, DP door update, KLD resampling) at 10,000 particles with 10 doors, and its memory at 50,000.

Scenes from ``bench_rbpf_doors.py`` (``dense``: all 10 doors in reach; ``corridor``: a few), rasterized into a
0.05 m occupancy map (walls only: the static map), 360-beam scans, Nav2's 60 beams for the weights. Every
timed update starts from the same particle set (a copy) with min_particles = max_particles = N, so that
KLD keeps N particles and resampling always runs (resample_neff_ratio 1.0): the worst case of one update.
Particle-beam evaluations/s = N·B / (time of the whole update).

Memory: peak traced NumPy memory of one update at 50,000 particles, the particle set included (tracemalloc),
and the process's peak RSS.

Also the tracked cloud's weighing alone (``tracked_log_likelihood``: static field, door terms, beam skipping, the
sum), the part ``localize.backend: torch`` runs on the device.

Run: ``taskset -c 0 python bench/bench_rbpf.py [--particles 10000 50000] [--repeats 5] [--torch-device cuda]``
(``--torch-device``: ``localize.backend: torch`` there: the tracked weighing on the device; the door update and
the conditioning on the beams stay in NumPy/numba).
"""

from __future__ import annotations

import argparse
import datetime
import math
import platform
import resource
import time
import tracemalloc

import numpy as np
from bench_rbpf_doors import RANGE_MAX_M, scan, scene

from doorbatch.config import LocalizeConfig
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.door_likelihood import numba_available
from doorbatch.pipeline.localize.likelihood_field import BeamCombination, BeamSet, build_distance_field
from doorbatch.pipeline.localize.mcl import MclState
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import rbpf_step, tracked_log_likelihood

RES = 0.05
TORCH_DEVICE: list[str | None] = [None]  # set from --torch-device


def rasterize(walls: np.ndarray) -> OccupancyMap:
    """Walls into a map_server-style grid: occupied on the walls, free elsewhere."""
    lo = walls.reshape(-1, 2).min(axis=0) - 1.0
    hi = walls.reshape(-1, 2).max(axis=0) + 1.0
    w, h = (np.ceil((hi - lo) / RES)).astype(int)
    occ = np.zeros((h, w), dtype=np.int8)
    grid = OccupancyMap(occ, RES, float(lo[0]), float(lo[1]))
    for a, b in walls:
        n = int(np.ceil(np.hypot(*(b - a)) / (RES / 4))) + 1
        ij = grid.world_to_cell(a + np.linspace(0.0, 1.0, n)[:, None] * (b - a))
        ok = grid.contains(ij)
        occ[ij[ok, 0], ij[ok, 1]] = 100
    return grid


def setup(name: str, n: int, rng: np.random.Generator) -> tuple[MclState, BeamSet, np.ndarray, object, object,
                                                                     LocalizeConfig]:
    walls, doors, angles, truth = scene(name)
    _, full = scan(walls, doors, angles, truth, rng)
    hit = np.isfinite(full).all(axis=1)
    sel = np.arange(0, full.shape[0], 6)
    sel = sel[hit[sel]]
    beams = BeamSet(full[sel].astype(np.float32), np.zeros(2), RANGE_MAX_M, sel.astype(np.int64))
    config = LocalizeConfig(min_particles=n, max_particles=n, resample_neff_ratio=1.0)
    field = build_distance_field(rasterize(walls), config.laser_likelihood_max_dist, torch_device=TORCH_DEVICE[0])
    particles = ParticleSet.gaussian(truth, (0.1, 0.1, math.radians(3.0)), n, rng, door_mean=angles,
                                     door_var=np.full(len(doors), math.radians(10.0) ** 2))
    particles.door_mean += rng.normal(0.0, math.radians(10.0), particles.door_mean.shape)
    odom_prev = np.zeros(3)
    state = MclState(particles, odom_at_update=odom_prev)
    return state, beams, full[hit], field, doors, config


def step_once(state: MclState, beams: BeamSet, pts: np.ndarray, field: object, doors: object,
              config: LocalizeConfig, rng: np.random.Generator) -> MclState:
    out, _, _ = rbpf_step(state, np.array([0.15, 0.0, 0.0]), 1.0, 0.9, beams, pts, field,  # type: ignore[arg-type]
                          doors, config, rng)  # type: ignore[arg-type]
    return out


def time_step(name: str, n: int, repeats: int) -> None:
    rng = np.random.default_rng(0)
    state, beams, pts, field, doors, config = setup(name, n, rng)
    step_once(state, beams, pts, field, doors, config, rng)  # compile / warm up
    best = math.inf
    for _ in range(repeats):
        fresh = MclState(state.particles.take(np.arange(n)), odom_at_update=state.odom_at_update)
        t0 = time.perf_counter()
        out = step_once(fresh, beams, pts, field, doors, config, rng)
        best = min(best, time.perf_counter() - t0)
    evals = n * len(beams.points_base)
    print(f"[{name}] N={n}, B={len(beams.points_base)}, D={len(doors)}: rbpf_step {best * 1e3:7.1f} ms = "  # type: ignore[arg-type]
          f"{evals / best / 1e6:5.2f} M particle-beams/s (N after: {len(out.particles)})")


def time_weigh(name: str, n: int, repeats: int) -> None:
    rng = np.random.default_rng(0)
    state, beams, _, field, doors, config = setup(name, n, rng)
    combination = BeamCombination(config.beam_combination)
    args = (state.particles, beams, field, doors, config, combination)
    tracked_log_likelihood(*args)  # type: ignore[arg-type]  # compile / warm up, the field to the device
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        tracked_log_likelihood(*args)  # type: ignore[arg-type]
        best = min(best, time.perf_counter() - t0)
    evals = n * len(beams.points_base)
    print(f"[{name}] N={n}: tracked weighing {best * 1e3:7.1f} ms = {evals / best / 1e6:5.2f} M particle-beams/s")


def memory(n: int) -> None:
    rng = np.random.default_rng(0)
    tracemalloc.start()
    base0 = tracemalloc.get_traced_memory()[0]
    state, beams, pts, field, doors, config = setup("dense", n, rng)
    base = tracemalloc.get_traced_memory()[0]
    tracemalloc.reset_peak()
    step_once(state, beams, pts, field, doors, config, rng)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"memory N={n}: state + map {(base - base0) / 2**20:.0f} MiB, peak during one update "
          f"{(peak - base0) / 2**20:.0f} MiB (traced), process peak RSS {rss:.0f} MiB")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--particles", type=int, nargs="+", default=[10000, 50000])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--torch-device", default=None, help="localize.backend: torch on this device")
    args = parser.parse_args()
    TORCH_DEVICE[0] = args.torch_device
    print(f"backend: {'numpy' if args.torch_device is None else 'torch on ' + args.torch_device}")
    print(f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, "
          f"{platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"numpy {np.__version__}, numba {'yes' if numba_available() else 'no'}")
    for name in ("dense", "corridor"):
        for n in args.particles:
            time_step(name, n, args.repeats)
            time_weigh(name, n, args.repeats)
    memory(max(args.particles))


if __name__ == "__main__":
    main()
