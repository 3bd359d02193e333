"""What a particle's pose region costs on one scan: the per-beam factors against the one pose volume factor.

For the scan at ``--scan`` of a log with a reference, at the reference pose, and for each bandwidth given
(position m, heading deg: the region a particle stands for, doorbatch/pipeline/localize/smoothing.py), prints
Σ_b log(σ/√(σ² + e_b)) (``global_smoothing_volume: per_beam``) and −½·log det(I + H·A) (``pose``).

Usage::

    python scripts/localize_region_factor.py datasets/sample/logs/loc_closed.mcap \
        --map datasets/sample/logs/loc_closed.map_closed.yaml [--scan 0] [--bandwidth 0.21 4.2 --bandwidth 0.03 0.5]
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.likelihood_field import beam_likelihood, endpoint_distances
from doorbatch.pipeline.localize.mcl import beams_from_scan
from doorbatch.pipeline.localize.run import laser_to_base_4x4, load_localization_map
from doorbatch.pipeline.localize.smoothing import (
    Bandwidth,
    endpoint_jacobians,
    endpoint_variance,
    pose_volume_log_factor,
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("log", type=Path)
    ap.add_argument("--map", type=Path, required=True, help="map_server YAML or map directory")
    ap.add_argument("--scan", type=int, default=0)
    ap.add_argument("--bandwidth", nargs=2, type=float, action="append", metavar=("XY_M", "YAW_DEG"))
    args = ap.parse_args()
    config = load_config()
    lc = config.localize
    lmap = load_localization_map(args.map, lc)
    rec = load_recording(args.log, config)
    if rec.reference is None:
        ap.error(f"{args.log} has no reference pose")
    stamp = rec.scans.stamps_ns[args.scan:args.scan + 1]
    pose, _ = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamp)
    beams = beams_from_scan(rec.scans.scan(args.scan), laser_to_base_4x4(rec.scans.laser_to_base[args.scan]), lc)
    dist = endpoint_distances(lmap.field, pose, beams.points_base)
    pz = beam_likelihood(dist, lc.z_hit, lc.z_rand, lc.sigma_hit, beams.range_max_m)
    hit_weight = (pz - lc.z_rand / beams.range_max_m) / pz
    jac = endpoint_jacobians(lmap.field, pose, beams.points_base)
    for h_xy, h_deg in args.bandwidth or [(0.21, 4.2), (0.03, 0.5)]:
        bw = Bandwidth(np.array([h_xy]), np.array([math.radians(h_deg)]))
        e = endpoint_variance(bw, beams.points_base)
        per_beam = float(np.sum(0.5 * np.log(lc.sigma_hit**2 / (lc.sigma_hit**2 + e))))
        volume = float(pose_volume_log_factor(jac, hit_weight, bw, lc.sigma_hit)[0])
        print(f"region {h_xy:g} m, {h_deg:g} deg, {len(beams)} beams: per-beam factors {per_beam:.1f} nats, "
              f"pose volume factor {volume:.1f} nats")


if __name__ == "__main__":
    main()
