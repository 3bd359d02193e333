"""Deskewing speed: scans per second of ``deskewed_scans`` (what ``load_recording`` adds for a laser that sets
time_increment), for an LDS-like 360-beam and a Hokuyo-like 1081-beam scan.

Random ranges in 0.5–10 m (every beam a hit: the most work), 25 Hz odometry of a robot driving 1 m/s and turning
1 rad/s; a sweep of 0.19 s (5 Hz) or 0.025 s (40 Hz). Timed by the process's CPU time, best of the repeats.

Run: ``taskset -c 0 python bench/bench_deskew.py [--scans N] [--repeats R]`` (one core, as in docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import math
import platform
import time

import numpy as np

from doorbatch.geometry.deskew import deskewed_scans


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f"{platform.processor() or platform.machine()}, numpy {np.__version__}")
    for beams, fov, rate_hz in ((360, 2 * math.pi, 5.0), (1081, math.radians(270), 40.0)):
        inc = fov / (beams if fov >= 2 * math.pi else beams - 1)
        sweep = 0.95 / rate_hz
        stamps = (np.arange(args.scans) * 1e9 / rate_hz).astype(np.int64)
        t_odom = np.arange(0, stamps[-1] + 2e9, 4e7).astype(np.int64)
        s = t_odom / 1e9
        odom = np.stack([np.sin(s), 1 - np.cos(s), s], axis=1)  # 1 m/s on a 1 m circle: 1 rad/s
        ranges = [rng.uniform(0.5, 10.0, beams).astype(np.float32) for _ in range(args.scans)]
        mount = np.array([[1.0, 0.0, 0.2], [0.0, 1.0, 0.0]])
        n = args.scans
        best = math.inf
        for _ in range(args.repeats):
            t0 = time.process_time()
            deskewed_scans(ranges, stamps, [sweep / (beams - 1)] * n, [-fov / 2] * n, [inc] * n, [0.05] * n,
                           [30.0] * n, [mount] * n, t_odom, odom)
            best = min(best, time.process_time() - t0)
        print(f"{beams} beams, {1e3 * sweep:.0f} ms sweep: {n / best:,.0f} scans/s ({1e6 * best / n:.0f} µs per scan)")


if __name__ == "__main__":
    main()
