"""The lost test's two measures at a pose per scan: hits near the map's walls (``scan_fit``) and beams through them
(``see_through_share``), at the true pose and at a run's estimate or a shifted one (docs/results.md, "A
localizer's own word").

Per log: the quantiles of both at the truth, the longest run of scans above 0.15 / 0.2 / 0.25 / 0.3 see-through
(what ``lost_after_s`` asks to last), and with an estimate the same where it is over 0.5 m off the truth.

Run: ``PYTHONPATH=. python scripts/localize_see_through.py LOG MAP.yaml TRUTH [RUNDIR|-] [DX,DY,DYAW]`` where
TRUTH is a TUM file or ``ref`` (the log's reference poses: a CARMEN log's corrected poses).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow.parquet as pq

from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.map_server import read_map
from doorbatch.io.recording import load_recording
from doorbatch.io.tum import read_tum
from doorbatch.pipeline.localize.convergence import scan_fit, see_through_share
from doorbatch.pipeline.localize.run import localization_field

FloatArray = npt.NDArray[np.float64]
THRESHOLDS = (0.1, 0.15, 0.2, 0.25)


def longest_run_s(stamps_s: FloatArray, mask: npt.NDArray[np.bool_]) -> float:
    """The longest span (s) of consecutive scans that all hold ``mask``."""
    best, start = 0.0, None
    for t, m in zip(stamps_s, mask, strict=True):
        start = (t if start is None else start) if m else None
        best = max(best, t - start) if start is not None else best
    return round(float(best), 1)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log", type=Path)
    parser.add_argument("map_yaml", type=Path)
    parser.add_argument("truth", help="TUM file, or 'ref' for the log's reference poses")
    parser.add_argument("run", nargs="?", default="-", help="a localize RUNDIR whose estimate to judge, or -")
    parser.add_argument("shift", nargs="?", default="", help="DX,DY,DYAW added to the truth instead of a run")
    args = parser.parse_args()
    config = load_config()
    lc = config.localize
    rec = load_recording(args.log, config)
    occ = read_map(args.map_yaml)
    field = localization_field(occ, lc)
    if args.truth == "ref":
        assert rec.reference is not None, "the log has no reference poses"
        truth, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns)
    else:
        tum = read_tum(Path(args.truth))
        truth, ok = interpolate_poses(tum.stamp_ns, np.stack([tum.x, tum.y, tum.yaw], 1), rec.scans.stamps_ns)
    other = None
    if args.run != "-":
        t = pq.read_table(Path(args.run) / "trajectory.parquet")
        poses = np.stack([t["x"].to_numpy(), t["y"].to_numpy(), t["yaw"].to_numpy()], 1)
        other, valid = interpolate_poses(t["stamp_ns"].to_numpy(), poses, rec.scans.stamps_ns)
        ok &= valid
    elif args.shift:
        other = truth + np.array([float(v) for v in args.shift.split(",")])
    idx = np.flatnonzero(ok)
    rows = []
    for i in idx:
        hits, origin = rec.scans.hits_base(i), rec.scans.laser_to_base[i][:, 2]
        row = []
        for pose in (truth[i], None if other is None else other[i]):
            if pose is None:
                row += [np.nan, np.nan]
                continue
            row += [scan_fit(field, pose, hits, lc.lost_fit_distance_m),
                    see_through_share(occ, field, pose, origin, hits, lc.lost_fit_distance_m, lc.map_occupied_at_least,
                                      lc.lost_see_through_beams)]
        rows.append(row)
    m = np.asarray(rows)
    stamps_s = rec.scans.stamps_ns[idx] / 1e9
    q = (0, 5, 50, 95, 100)
    runs = [longest_run_s(stamps_s, m[:, 1] > t) for t in THRESHOLDS]
    print(f"truth: fit {np.nanpercentile(m[:, 0], q).round(3)}, see-through {np.nanpercentile(m[:, 1], q).round(3)}, "
          f"longest run (s) over {THRESHOLDS}: {runs}")
    if other is not None:
        off = np.hypot(*(other[idx, :2] - truth[idx, :2]).T) > 0.5
        for name, sel in (("over 0.5 m off", off), ("within 0.5 m", ~off)):
            if sel.any():
                fit, through = np.nanpercentile(m[sel, 2], q).round(3), np.nanpercentile(m[sel, 3], q).round(3)
                print(f"estimate {name} ({int(sel.sum())} of {len(sel)} scans): fit {fit}, see-through {through}")
        runs = [longest_run_s(stamps_s, m[:, 3] > t) for t in THRESHOLDS]
        print(f"estimate: longest run (s) over {THRESHOLDS}: {runs}")


if __name__ == "__main__":
    main()
