"""Range-only EM (paper 001) on the real CARMEN logs of ``../shared/datasets/carmen/``: wall-segment maps
and what the model calls doors.

Each log's corrected poses are the reference; the log is cut into ``--passes`` passes of equal duration
(doors may move between them: the robots revisit their corridors), every ``--scan-stride``-th scan (the
final wall step of the stage runs over every scan and beam: ``em.final_scan_stride``, ``final_beam_stride``).
The logs have no colour, so the EM is range only. Writes ``docs/img/em_carmen_<log>.png`` (laser end
points white on grey, EM walls dark blue, doors red when they moved between passes, orange otherwise)
and prints one row per log.

Usage::

    python scripts/em_carmen.py [--passes 3] [--scan-stride 1] [--beam-stride 1] [--out docs/img]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.preview import render_preview, write_preview
from doorbatch.io.recording import load_recording
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.mapping import pass_poses
from doorbatch.pipeline.objectmap.beams import BeamSet, beams_from_scans
from doorbatch.pipeline.objectmap.stage import FinalStepBeams, build_object_map, pass_scans

ROOT = Path(__file__).resolve().parents[1]
CARMEN = ROOT.parent / "shared" / "datasets" / "carmen"


def points_map(beams: BeamSet, resolution_m: float = 0.05) -> OccupancyMap:
    """A grid where cells with a laser end point are 'free' (drawn white) and the rest unknown."""
    pts = beams.points[beams.hit]
    lo = pts.min(axis=0) - 1.0
    size = np.ceil((pts.max(axis=0) + 1.0 - lo) / resolution_m).astype(int)
    grid = np.full((size[1], size[0]), -1, dtype=np.int8)
    ij = np.floor((pts - lo) / resolution_m).astype(int)
    grid[ij[:, 1], ij[:, 0]] = 0
    return OccupancyMap(grid, resolution_m, float(lo[0]), float(lo[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--passes", type=int, default=3)
    ap.add_argument("--scan-stride", type=int, default=1)
    ap.add_argument("--beam-stride", type=int, default=1)
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    args = ap.parse_args()
    config = DoorbatchConfig()
    em = config.em.model_copy(update={"use_color": False, "scan_stride": args.scan_stride,
                                      "beam_stride": args.beam_stride, "final_scan_stride": 1,
                                      "final_beam_stride": 1})
    rows = []
    for path in sorted(CARMEN.glob("*.log*")):
        rec = load_recording(path, config)
        poses = pass_poses(rec, "reference", config)
        every_scan = pass_scans(rec, poses, 1, em)
        passes = [[every_scan[i] for i in c] for c in np.array_split(np.arange(len(every_scan)), args.passes)]
        scans = [sc for p in passes for sc in p[::em.scan_stride]]
        beams = beams_from_scans([p[::em.scan_stride] for p in passes], em.max_range_m, em.beam_stride)
        final_beams = beams_from_scans([p[::em.final_scan_stride] for p in passes], em.max_range_m,
                                       em.final_beam_stride)
        final = FinalStepBeams(final_beams, 1, sum(map(len, passes)), len(final_beams))
        result = build_object_map(beams, em, final=final)
        walls = [w.endpoints() for w in result.object_map.walls if w.segments.size]
        image = render_preview(points_map(beams), [d.preview for d in result.doors],
                               walls=np.concatenate(walls) if walls else None)
        name = path.name.split(".")[0]
        write_preview(args.out / f"em_carmen_{name}.png", image)
        rows.append({"log": name, "scans": len(scans), "beams": result.n_beams, "walls": len(result.object_map.walls),
                     "segments": int(sum(w.segments.shape[0] for w in result.object_map.walls)),
                     "wall_length_m": round(sum(w.length for w in result.object_map.walls), 1),
                     "doors": len(result.doors), "moved_doors": sum(d.preview.moved for d in result.doors),
                     "door_width_m": round(result.object_map.classes.door_width_m, 2),
                     "seconds": round(result.seconds, 1)})
        print(json.dumps(rows[-1]), flush=True)


if __name__ == "__main__":
    main()
