"""RBPF door parts (paper 000, Sec. IV): door-aware beam likelihood (eq. (6)) and the per-scan door update.

Two simulated scenes with 10 doors: ``dense``, a 12 m corridor with 5 doors on each side, all in reach of the
scan (the worst case: the reach pre-filter keeps every door); ``corridor``, a 50 m corridor with 10 doors, of
which the scan reaches a few (the usual case). Scans are cast exactly against the walls and the leaves
(360 beams, 1 cm noise); the likelihood uses 60 of them (Nav2's max_beams), the door update all of them.
Particles are spread around the true pose (0.2 m, 5°), door means around the true angles (10°).

Timed (best of the repeats): ``door_log_likelihood`` with (N, B, 2) end points and
``door_log_likelihood_at_poses`` (particle-beam evaluations per second), and
``update_doors`` (Douglas–Peucker + association + Kalman). The static likelihood-field distances are an input
of the door likelihood (MCL's field lookup); here they are exact distances to the walls, computed untimed.
The peak traced NumPy memory of both calls is printed for the largest particle count.

Run: ``taskset -c 0 python bench/bench_rbpf_doors.py [--particles 10000 50000] [--repeats 5]`` (one core, as
in docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import math
import platform
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_geometry import leaf_endpoints
from doorbatch.pipeline.localize.door_likelihood import (
    door_log_likelihood,
    door_log_likelihood_at_poses,
    numba_available,
)
from doorbatch.pipeline.localize.door_observation import update_doors
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.sim.raycast import cast_rays

FloatArray = npt.NDArray[np.float64]
LEAF_M = 0.9
RANGE_MAX_M = 15.0


def scene(name: str) -> tuple[FloatArray, DoorSet, FloatArray, FloatArray]:
    """Walls (S, 2, 2) with doorways, 10 doors, their true angles, and the robot pose."""
    if name == "dense":
        xs, length, pose = np.array([1.0, 3.5, 6.0, 8.5, 11.0]), 12.0, np.array([6.2, 1.0, 0.3])
    else:
        xs, length, pose = np.linspace(3.0, 45.0, 5), 50.0, np.array([14.0, 1.0, 0.1])
    walls, hinges, yaws = [], [], []
    for side, y in ((0, 0.0), (1, 2.0)):
        x0 = 0.0
        for x in xs + 0.3 * side:
            walls.append([[x0, y], [x, y]])
            hinges.append([x, y])
            yaws.append(0.0)
            x0 = x + LEAF_M
        walls.append([[x0, y], [length, y]])
    walls += [[[0.0, 0.0], [0.0, 2.0]], [[length, 0.0], [length, 2.0]]]
    for x in range(0, int(length), 4):  # back walls of the rooms behind the doors
        walls += [[[x, -3.0], [x + 3.5, -3.0]], [[x, 5.0], [x + 3.5, 5.0]]]
    n = len(hinges)
    sign = np.where(np.arange(n) < n // 2, -1.0, 1.0)  # doors open away from the corridor
    doors = DoorSet(hinge=np.asarray(hinges), length=np.full(n, LEAF_M), closed_yaw=np.asarray(yaws),
                    angle_min=np.minimum(0.0, sign * np.pi / 2), angle_max=np.maximum(0.0, sign * np.pi / 2))
    angles = sign * np.deg2rad([40, 2, 70, 0, 25, 90, 15, 55, 5, 30])[:n]
    return np.asarray(walls, dtype=np.float64), doors, angles, pose


def scan(walls: FloatArray, doors: DoorSet, angles: FloatArray, pose: FloatArray, rng: np.random.Generator
         ) -> tuple[FloatArray, FloatArray]:
    """360-beam scan from pose: (B,) bearings and (B, 2) hit points in base_link (NaN beyond range)."""
    ends = leaf_endpoints(doors, angles[None])[0]
    segments = np.concatenate([walls, np.stack([doors.hinge, ends], axis=1)])
    bearing = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    world = bearing + pose[2]
    ranges, _ = cast_rays(pose[:2], np.stack([np.cos(world), np.sin(world)], axis=1), segments)
    ranges = ranges + rng.normal(0.0, 0.01, ranges.size)
    ranges[~(ranges < RANGE_MAX_M)] = np.nan
    return bearing, np.stack([ranges * np.cos(bearing), ranges * np.sin(bearing)], axis=1)


def endpoints(points_base: FloatArray, pose: FloatArray) -> FloatArray:
    """Beam end points (N, B, 2) in the map frame at every particle pose."""
    c, s = np.cos(pose[:, 2])[:, None], np.sin(pose[:, 2])[:, None]
    x, y = points_base[None, :, 0], points_base[None, :, 1]
    return np.stack([c * x - s * y + pose[:, 0, None], s * x + c * y + pose[:, 1, None]], axis=-1)


def wall_distance(points: FloatArray, walls: FloatArray, cap: float) -> FloatArray:
    """Stand-in for the likelihood field: exact distance to the nearest wall, capped (untimed)."""
    flat = points.reshape(-1, 2)
    out = np.full(flat.shape[0], cap)
    a, e = walls[:, 0], walls[:, 1] - walls[:, 0]
    for lo in range(0, flat.shape[0], 20000):
        p = flat[lo:lo + 20000, None, :]
        t = np.clip(np.sum((p - a) * e, axis=2) / np.sum(e * e, axis=1), 0.0, 1.0)
        d = np.hypot(*np.moveaxis(p - a - t[..., None] * e, -1, 0)).min(axis=1)
        out[lo:lo + 20000] = np.minimum(d, cap)
    return np.where(np.isfinite(flat).all(axis=1), out, np.nan).reshape(points.shape[:-1])


def best_time(fn: Callable[[], Any], repeats: int) -> float:
    """Best wall time of ``repeats`` calls (s)."""
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - start)
    return best


def run(name: str, n: int, repeats: int, config: LocalizeConfig, rng: np.random.Generator) -> None:
    walls, doors, angles, truth = scene(name)
    _, full = scan(walls, doors, angles, truth, rng)
    beams = full[::6]  # 60 beams
    particles = ParticleSet.gaussian(truth, (0.2, 0.2, np.deg2rad(5.0)), n, rng,
                                     door_mean=angles, door_var=np.full(len(doors), np.deg2rad(10.0) ** 2))
    particles.door_mean += rng.normal(0.0, np.deg2rad(10.0), particles.door_mean.shape)
    points = endpoints(beams, particles.pose)
    static = wall_distance(points, walls, config.laser_likelihood_max_dist)
    mean, var = particles.door_mean, particles.door_var
    reach = int(np.sum(np.hypot(*(doors.hinge - truth[:2]).T) < RANGE_MAX_M + LEAF_M))

    def lik(backend: str) -> Callable[[], Any]:
        return lambda: door_log_likelihood(static, points, doors, mean, var, config, RANGE_MAX_M, backend=backend)

    def lik_at_poses() -> Any:
        return door_log_likelihood_at_poses(static, particles.pose, beams, doors, mean, var, config, RANGE_MAX_M)

    def upd() -> Any:
        return update_doors(full, particles, doors, config)

    lik("auto")()
    lik_at_poses()
    upd()  # compile / warm up
    t_lik = best_time(lik("auto"), repeats)
    t_pose = best_time(lik_at_poses, repeats)
    t_np = best_time(lik("numpy"), max(1, repeats // 2))
    t_upd = best_time(upd, repeats)
    res = door_log_likelihood(static, points, doors, mean, var, config, RANGE_MAX_M)
    obs = upd().observed
    print(f"[{name}] N={n}, B={beams.shape[0]}, D={len(doors)} ({reach} in laser reach), "
          f"door-associated beams {np.mean(res.association >= 0):.1%}, doors observed/particle "
          f"{obs.sum(axis=1).mean():.1f}")
    evals = n * beams.shape[0] / 1e6
    print(f"  door likelihood (numba): {t_lik * 1e3:7.1f} ms = {evals / t_lik:6.1f} M particle-beams/s")
    print(f"  door likelihood at poses (numba, no (N, B, 2) input): {t_pose * 1e3:7.1f} ms = "
          f"{evals / t_pose:6.1f} M particle-beams/s")
    print(f"  door likelihood (numpy): {t_np * 1e3:7.1f} ms = {evals / t_np:6.1f} M particle-beams/s")
    print(f"  door update (DP + association + Kalman, {np.isfinite(full).all(axis=1).sum()} points): "
          f"{t_upd * 1e3:7.1f} ms")


def peak_memory(n: int, config: LocalizeConfig, rng: np.random.Generator) -> None:
    """Peak traced memory of one likelihood + door update at N particles (inputs included)."""
    walls, doors, angles, truth = scene("dense")
    _, full = scan(walls, doors, angles, truth, rng)
    tracemalloc.start()
    particles = ParticleSet.gaussian(truth, (0.2, 0.2, np.deg2rad(5.0)), n, rng, door_mean=angles,
                                     door_var=np.full(len(doors), 0.03))
    points = endpoints(full[::6], particles.pose)
    static = np.zeros(points.shape[:-1])
    base = tracemalloc.get_traced_memory()[0]
    for backend in ("auto", "numpy"):
        tracemalloc.reset_peak()
        door_log_likelihood(static, points, doors, particles.door_mean, particles.door_var, config, RANGE_MAX_M,
                            backend=backend)
        update_doors(full, particles, doors, config)
        peak = tracemalloc.get_traced_memory()[1]
        print(f"  N={n}: inputs {base / 2**20:.0f} MiB (particles, end points, static distances); peak during "
              f"likelihood ({backend}) + door update {peak / 2**20:.0f} MiB")
    tracemalloc.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--particles", type=int, nargs="+", default=[10000, 50000])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    config = LocalizeConfig()
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"numpy {np.__version__}, numba {'yes' if numba_available() else 'no'}")
    for name in ("dense", "corridor"):
        for n in args.particles:
            run(name, n, args.repeats, config, np.random.default_rng(0))
    peak_memory(max(args.particles), config, np.random.default_rng(0))


if __name__ == "__main__":
    main()
