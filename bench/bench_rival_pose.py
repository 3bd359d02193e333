"""The rival test's cost: one search of the whole map for a second pose where a run's scans fit as well.

It runs once per global run that claims convergence, after the run. The cloud here is every scan of a log placed at
its reference pose (the longest span a claim can cover), in the frame of the last pose. Logs: the sample's
loc_partial on the truth's static map (or ``--map``), and, where ``../shared/datasets/carmen`` is present, the three
CARMEN logs on maps built from their corrected poses (grid stage). Per log: points, the time of the test with the
defaults, and the candidate with the least evidence against it when the search bar is lowered to 0.5 (how far the log
is from ambiguous: its score's share of the estimate's, and the metres of wall only the estimate explains). Timed by
the process's CPU time, best of the repeats.

Run: ``taskset -c 0 python bench/bench_rival_pose.py [--map MAP.yaml] [--repeats R]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import platform
import time
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.io.map_server import read_map
from doorbatch.io.recording import Recording, load_recording
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.rival_pose import RivalSearch, find_rival, scan_cloud
from doorbatch.pipeline.localize.run import LocalizationMap
from doorbatch.pipeline.mapping import build_map

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "datasets" / "sample" / "logs"
CARMEN = ROOT.parent / "shared" / "datasets" / "carmen"


def measure(name: str, rec: Recording, occ: OccupancyMap, repeats: int) -> None:
    lc = load_config().localize
    lmap = LocalizationMap.of(occ, DoorSet.empty(), lc)
    assert rec.reference is not None
    at = np.clip(np.searchsorted(rec.reference.stamps_ns, rec.scans.stamps_ns), 0, len(rec.reference) - 1)
    poses = rec.reference.poses[at]
    cloud = scan_cloud(poses, [rec.scans.hits_base(i) for i in range(len(rec.scans))], poses[-1],
                       lc.rival_resolution_m, lc.rival_cloud_points)
    settings = RivalSearch(lc.rival_resolution_m, lc.rival_sigma_m, lc.rival_search_ratio, lc.rival_search_points,
                           lc.rival_min_evidence_m, lc.rival_max_candidates, lc.ambiguity_radius_m,
                           math.radians(lc.ambiguity_yaw_deg))
    best = math.inf
    for _ in range(repeats):
        t = time.process_time()
        found = find_rival(lmap.field, lmap.free.free_mask, poses[-1], cloud, settings)
        best = min(best, time.process_time() - t)
    low = find_rival(lmap.field, lmap.free.free_mask, poses[-1], cloud,
                     dataclasses.replace(settings, search_ratio=0.5))
    n = low.nearest
    nearest = "none scores 0.5" if n is None else f"{n.ratio:.2f} of the own score, {n.evidence_m:.1f} m of evidence"
    verdict = "undecided" if found.undecided else "rival" if found.rival is not None else "no rival"
    print(f"{name}: map {occ.width}×{occ.height} cells, {len(rec.scans)} scans → {found.points} points: {verdict}, "
          f"{best:.2f} s CPU; the nearest candidate at a search bar of 0.5: {nearest}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", type=Path, default=SAMPLE / "map.map_static.yaml")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    print(f"{platform.processor() or platform.machine()}, numpy {np.__version__}")
    measure("sample loc_partial", load_recording(SAMPLE / "loc_partial.mcap"), read_map(args.map), args.repeats)
    for log in ("orebro", "intel", "aces"):
        path = CARMEN / f"{log}-corrected.log.gz"
        if not path.is_file():
            continue
        config = load_config(None, ["mapping.pose_source=reference"])
        occ = build_map([path], config).static_map
        measure(log, load_recording(path, config), occ, args.repeats)


if __name__ == "__main__":
    main()
