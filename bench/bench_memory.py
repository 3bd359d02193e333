"""Streaming check: peak memory while reading every scan of a large MCAP stays flat as the log grows.

Run: ``python bench/bench_memory.py --gigabytes 0.2 2.0``. Each size runs in a fresh process so the peak RSS
(``ru_maxrss``) belongs to that read alone.
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

SCAN_BYTES = 1081 * 4 + 100  # one 1081-beam LaserScan, CDR


def read_all(path: Path) -> None:
    from doorbatch.io.reader import open_log
    from doorbatch.records import Role

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with open_log(path) as reader:
        n = sum(1 for _ in reader.messages([Role.SCAN]))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"{path.stat().st_size / 1e9:.2f} GB, {n} scans: peak RSS {peak / 1024:.0f} MiB "
          f"(after imports {before / 1024:.0f} MiB)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--gigabytes", type=float, nargs="+", default=[0.2, 2.0])
    parser.add_argument("--read", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.read:
        read_all(args.read)
        return
    sys.path.insert(0, str(Path(__file__).parent))
    from bench_read import write

    with tempfile.TemporaryDirectory() as tmp:
        for gb in args.gigabytes:
            path = Path(tmp) / f"big_{gb}.mcap"
            write(path, "mcap", int(gb * 1e9 / SCAN_BYTES))
            subprocess.run([sys.executable, __file__, "--read", str(path)], check=True)
            path.unlink()


if __name__ == "__main__":
    main()
