"""The lost test's cost per filter update: ``scan_fit`` and ``see_through_share`` at the cloud's mean.

Both run once per update at one pose (not per particle). The sample's loc_partial scans (360 beams, 10 m) on the
map built from the sample's passes (or the truth's static map when none is given), then a 1081-beam scan made by
repeating each beam's range three times (a Hokuyo's density). Timed by the process's CPU time, best of the repeats.

Run: ``taskset -c 0 python bench/bench_lost_test.py [--map MAP.yaml] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import platform
import time
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.io.map_server import read_map
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.convergence import scan_fit, see_through_share
from doorbatch.pipeline.localize.run import localization_field

SAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "sample" / "logs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", type=Path, default=SAMPLE / "map.map_static.yaml")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    lc = load_config().localize
    rec = load_recording(SAMPLE / "loc_partial.mcap")
    occ = read_map(args.map)
    field = localization_field(occ, lc)
    assert rec.reference is not None
    poses = rec.reference.poses[:: max(1, len(rec.reference) // 200)][:200]
    hits = [rec.scans.hits_base(i) for i in range(0, 200)]
    dense = [np.repeat(h, 3, axis=0) for h in hits]
    origin = rec.scans.laser_to_base[0][:, 2]
    print(f"{platform.processor() or platform.machine()}, numpy {np.__version__}, {len(poses)} updates")
    for name, scans in (("360 beams", hits), ("1081 beams", dense)):
        for what, fn in (("scan_fit", lambda p, h: scan_fit(field, p, h, lc.lost_fit_distance_m)),
                         ("see_through_share", lambda p, h: see_through_share(
                             occ, field, p, origin, h, lc.lost_fit_distance_m, lc.map_occupied_at_least,
                             lc.lost_see_through_beams))):
            best = float("inf")
            for _ in range(args.repeats):
                t = time.process_time()
                for p, h in zip(poses, scans, strict=False):
                    fn(p, h)
                best = min(best, (time.process_time() - t) / len(poses))
            print(f"{name}: {what} {best * 1e3:.2f} ms per update")


if __name__ == "__main__":
    main()
