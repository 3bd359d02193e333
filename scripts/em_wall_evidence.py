"""Would a wall on a given line pay for itself (paper 001 eq. 9 and the prior's 2ρS for the line)? On site A
of ``scripts/em_acceptance.py``, against the stage's map without its final wall step, once on the kept beams
(every scan_stride-th scan, beam_stride-th beam) and once on every scan and beam.

Prints, per beam set: the truth wall's hits on that line (ray-cast attribution), the DP's segments and its
optimal cost (the gains Σ Δ less ρL·length and 2ρS per segment; 0 = no segment), and that cost plus the
line's own 2ρS (negative: the wall raises the log posterior).

Usage::

    python scripts/em_wall_evidence.py --work DIR --line NX,NY,OFFSET     (the line n·p = offset)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from em_acceptance import hits_by_truth_segment, load_site, run

from doorbatch.config import DoorbatchConfig
from doorbatch.pipeline.objectmap.sensor import first_objects
from doorbatch.pipeline.objectmap.stage import collect_beams
from doorbatch.pipeline.objectmap.walls import wall_segments


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, required=True, help="site A's logs (simulated there if absent)")
    ap.add_argument("--line", required=True, help="NX,NY,OFFSET of the line n·p = offset (n a unit vector)")
    args = ap.parse_args()
    nx, ny, offset = (float(v) for v in args.line.split(","))
    normal = np.array([nx, ny]) / np.hypot(nx, ny)
    config = DoorbatchConfig()
    em = config.em.model_copy(update={"final_recut_sweeps": 0})
    site = load_site("em_corridor", 5, args.work, config)
    result, kept = run(site, em)
    segs = site.truth.segments
    d = segs[:, 1] - segs[:, 0]
    on_line = np.abs(np.abs(d / np.linalg.norm(d, axis=1, keepdims=True) @ normal)) < 1e-6
    on_line &= np.abs(segs[:, 0] @ normal - offset) < 0.05
    for name, beams in (("kept beams", kept), ("every scan and beam", collect_beams(site.recordings, site.passes, em,
                                                                                    (1, 1)))):
        own = hits_by_truth_segment(beams, segs)
        first = first_objects(beams, result.object_map)
        found, cost = wall_segments(beams, first, result.object_map, -1, normal, offset, em.validity_prior, em.sigma_m,
                                    em.rho_length_per_m, 2.0 * em.rho_static)
        print(json.dumps({"beams": name, "truth_hits_on_line": int(sum(len(own[k]) for k in np.flatnonzero(on_line))),
                          "segments": np.round(found, 2).tolist(), "dp_cost": round(cost, 1),
                          "with_line_2rho_s": round(cost + 2.0 * em.rho_static, 1) if found.size else 0.0}))


if __name__ == "__main__":
    main()
