"""Tracking from a start that is off by a known shift: how far does the robot drive before the filter is back?

The filter starts at the log's first reference pose moved by (dx, dy) (``--init X,Y,YAW``, spread
``init_sigma_xy_m``), so the truth may lie outside the initial cloud. Printed per run: the position RMSE, the
mean error over the last 10 updates, the signed error along x (estimate − truth) averaged over stretches of
``--bin-m`` of the true x, and the true x from which the error stays below ``--recovered-m`` to the end.
On a straight corridor this shows where the scans first fix the axis, and how long beam skipping
(``do_beamskip``) holds a cloud whose error exceeds ``beam_skip_distance`` (docs/results.md, issue #5).

Usage::

    python scripts/localize_offset_start.py LOG --map MAPDIR|MAP.yaml [--methods mcl rbpf]
        [--shifts -0.8 -0.4 0.4 0.8] [--set localize.do_beamskip=false]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.evaluate.trajectory_metrics import ape_translation
from doorbatch.pipeline.localize.run import load_localization_map, localize_recording


def recovered_from_x(err_m: np.ndarray, x_m: np.ndarray, limit_m: float) -> float:
    """The true x of the first update after which the error stays ≤ ``limit_m`` (NaN: never)."""
    bad = np.flatnonzero(err_m > limit_m)
    if bad.size == 0:
        return float(x_m[0])
    return float(x_m[bad[-1] + 1]) if bad[-1] + 1 < x_m.size else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--map", type=Path, required=True, help="map directory or map_server YAML")
    ap.add_argument("--methods", nargs="+", default=["mcl", "rbpf"])
    ap.add_argument("--shifts", nargs="+", type=float, default=[-0.8, -0.4, 0.4, 0.8], help="dx of the start, m")
    ap.add_argument("--dy", type=float, default=0.0, help="dy of the start, m")
    ap.add_argument("--bin-m", type=float, default=4.0)
    ap.add_argument("--recovered-m", type=float, default=0.1)
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    args = ap.parse_args()
    config = load_config(overrides=args.overrides)
    rec = load_recording(args.log, config)
    if rec.reference is None:
        ap.error(f"{args.log} has no reference poses")
    lmap = load_localization_map(args.map, config.localize)
    start = rec.reference.poses[0]
    print(f"{args.log.name} on {args.map}, overrides {args.overrides or 'none'}")
    for method in args.methods:
        for dx in args.shifts:
            res = localize_recording(rec, lmap, config, method, (start[0] + dx, start[1] + args.dy, start[2]))
            ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, res.stamps_ns,
                                        round(config.evaluate.global_success_max_reference_gap_s * 1e9))
            est, ref = res.pose[ok], ref[ok]
            err = ape_translation(est, ref)
            ex = est[:, 0] - ref[:, 0]
            edges = np.arange(np.floor(ref[:, 0].min()), ref[:, 0].max() + args.bin_m, args.bin_m)
            stretch = " ".join(f"{a:.0f}:{ex[(ref[:, 0] >= a) & (ref[:, 0] < a + args.bin_m)].mean():+.2f}"
                               for a in edges if ((ref[:, 0] >= a) & (ref[:, 0] < a + args.bin_m)).any())
            back = recovered_from_x(err, ref[:, 0], args.recovered_m)
            print(f"{method:4s} dx {dx:+.2f}: RMSE {np.sqrt(np.mean(err ** 2)):.3f} m, last 10 "
                  f"{err[-10:].mean():.3f} m, within {args.recovered_m} m from x = {back:.1f} | x error by true "
                  f"x: {stretch}")


if __name__ == "__main__":
    main()
