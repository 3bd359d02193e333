"""Scan matching speed: scans per second of ``scan_match_trajectory`` on a simulated 360-beam corridor.

A 30 m × 2 m corridor with niches on both walls; the robot drives along it and back at 1 m/s with a 10 Hz
laser (0.1 m between scans), with drifting odometry (3 % scale error, 0.6°/m yaw bias, white noise).
Ray casting uses ``doorbatch.sim.raycast``; only ``scan_match_trajectory`` is timed (best of the repeats), by the
wall clock and by the process's CPU time (the latter is what a shared machine does not distort).

Run: ``taskset -c 0 python bench/bench_scanmatch.py [--scans N] [--repeats R] [--no-loop-closure]`` (one core, as
in docs/benchmarks.md; loop closure is on by default, as in the config; the corridor's way back is where it closes).
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import compose, relative
from doorbatch.pipeline.poses import ScanMatchConfig, scan_match_trajectory
from doorbatch.sim.raycast import cast_rays

FloatArray = npt.NDArray[np.float64]
LENGTH_M = 30.0


def corridor(rng: np.random.Generator) -> FloatArray:
    """Wall segments (S, 2, 2): two long walls with random niches, closed ends."""
    segments = []
    for side in (-1.0, 1.0):
        pts = [(-1.0, side)]
        x = 0.5
        while x < LENGTH_M - 2.0:
            x += rng.uniform(1.5, 4.0)
            width, depth = rng.uniform(0.6, 1.3), rng.uniform(0.3, 0.6)
            pts += [(x, side), (x, side * (1 + depth)), (x + width, side * (1 + depth)), (x + width, side)]
            x += width
        pts.append((LENGTH_M + 1.0, side))
        p = np.asarray(pts)
        segments.append(np.stack([p[:-1], p[1:]], axis=1))
    ends = np.array([[[-1.0, -1.0], [-1.0, 1.0]], [[LENGTH_M + 1, -1.0], [LENGTH_M + 1, 1.0]]])
    return np.concatenate([*segments, ends])


def trajectory(n: int) -> FloatArray:
    """Poses along the corridor (0.1 m per scan), a turn on the spot (10° per scan), and back."""
    turn = 18
    leg = (n - turn) // 2
    s = np.concatenate([0.1 * np.arange(leg), np.full(turn, 0.1 * leg), 0.1 * (leg - 1 - np.arange(n - leg - turn))])
    yaw = np.concatenate([np.zeros(leg), np.deg2rad(10.0) * np.arange(1, turn + 1), np.full(n - leg - turn, np.pi)])
    x = 0.5 + np.minimum(s, LENGTH_M - 1.0)  # longer runs wait at the far end
    return np.stack([x, 0.2 * np.sin(x / 3.0), yaw], axis=1)


def scans_from(segments: FloatArray, poses: FloatArray, rng: np.random.Generator) -> list[FloatArray]:
    """360-beam scans (hit points in base_link, 1 cm noise, 10 m range) from every pose."""
    angles = np.linspace(-np.pi, np.pi, 360, endpoint=False)
    out = []
    for pose in poses:
        world = angles + pose[2]
        ranges, _ = cast_rays(pose[:2], np.stack([np.cos(world), np.sin(world)], axis=1), segments)
        ranges = ranges + rng.normal(0.0, 0.01, angles.size)
        hit = np.isfinite(ranges) & (ranges < 10.0)
        out.append(np.stack([ranges[hit] * np.cos(angles[hit]), ranges[hit] * np.sin(angles[hit])], axis=1))
    return out


def odometry(truth: FloatArray, rng: np.random.Generator) -> FloatArray:
    """Truth increments with scale error, yaw bias and noise, integrated from the first pose."""
    inc = relative(truth[:-1], truth[1:])
    dist = np.hypot(inc[:, 0], inc[:, 1])
    inc[:, :2] = 1.03 * inc[:, :2] + rng.normal(0.0, 0.005, (len(inc), 2))
    inc[:, 2] += np.deg2rad(0.6) * dist + rng.normal(0.0, np.deg2rad(0.2), len(inc))
    odom = [truth[0]]
    for step in inc:
        odom.append(compose(odom[-1], step))
    return np.asarray(odom)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scans", type=int, default=600)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--no-loop-closure", action="store_true",
                        help="the front end alone (scanmatch.loop_closure off)")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    truth = trajectory(args.scans)
    scans = scans_from(corridor(rng), truth, rng)
    odom = odometry(truth, rng)
    config = ScanMatchConfig(loop_closure=not args.no_loop_closure)
    best, best_cpu, result = 0.0, 0.0, None
    for _ in range(args.repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = scan_match_trajectory(scans, odom, config)
        best = max(best, len(scans) / (time.perf_counter() - start))
        best_cpu = max(best_cpu, len(scans) / (time.process_time() - start_cpu))
    assert result is not None
    err = np.hypot(*(result.poses[:, :2] - truth[:, :2]).T)
    raw = np.hypot(*(odom[:, :2] - truth[:, :2]).T)
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"scan_match_trajectory: {best:.0f} scans/s wall, {best_cpu:.0f} scans per CPU-second ({len(scans)} scans, "
          f"{np.mean([len(s) for s in scans]):.0f}"
          f" points/scan, {int(result.keyframe.sum())} keyframes, {int(result.fallback.sum())} fallbacks, "
          f"loop closure {'off' if args.no_loop_closure else 'on'}: {int(result.loop_closure.sum())} loop keyframes)")
    print(f"ATE RMSE: odometry {np.sqrt(np.mean(raw**2)):.3f} m, scan matching {np.sqrt(np.mean(err**2)):.3f} m")


if __name__ == "__main__":
    main()
