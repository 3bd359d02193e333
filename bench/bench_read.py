"""Reading speed: scans per second through doorbatch's readers (1081-beam scans), MCAP and ROS 1 bag.

Run: ``python bench/bench_read.py [--scans N]``. Pinned to one core with ``taskset -c 0`` for the figure in
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from doorbatch.io import ros_messages as m
from doorbatch.io.log_writer import LogWriter
from doorbatch.io.reader import open_log
from doorbatch.records import Role

T0 = 1_700_000_000_000_000_000


def write(path: Path, fmt: str, n_scans: int, beams: int = 1081) -> None:
    rng = np.random.default_rng(0)
    ranges = rng.uniform(0.1, 30.0, (64, beams)).astype(np.float32)
    inc = np.deg2rad(270.0) / (beams - 1)
    with LogWriter(path, fmt) as w:
        for i in range(n_scans):
            t = T0 + i * 25_000_000
            w.write("/scan", "sensor_msgs/msg/LaserScan", t,
                    m.laser_scan(t, "laser", -np.deg2rad(135.0), inc, 0.05, 30.0, ranges[i % 64]))


def measure(path: Path, repeats: int = 3) -> float:
    best = 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        with open_log(path) as reader:
            n = sum(1 for _ in reader.messages([Role.SCAN]))
        best = max(best, n / (time.perf_counter() - start))
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--scans", type=int, default=20_000)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        for fmt, name in (("mcap", "scans.mcap"), ("bag", "scans.bag"), ("rosbag2", "scans_sqlite3")):
            path = Path(tmp) / name
            write(path, fmt, args.scans)
            print(f"{fmt:8s} {args.scans} scans x 1081 beams: {measure(path):,.0f} scans/s")


if __name__ == "__main__":
    main()
