"""Score ``doorbatch map`` against simulated ground truth: doors (precision, recall, hinge / length /
opening-range errors), static map agreement, spurious occupied cells, and the pose source's ATE.

Usage: ``python scripts/score_gridmap.py MAPDIR TRUTH.yaml [--json]`` — TRUTH is the simulator's truth
file of the mapping run (``<log>.truth.yaml``); its door-less static map is read from beside it.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.map_server import read_map
from doorbatch.io.mapdir import read_door_set
from doorbatch.io.sim_truth import read_truth
from doorbatch.pipeline.evaluate.door_map import score_doors, score_static_occupancy, truth_doors


def score(map_dir: Path, truth_path: Path, min_opening_deg: float | None = None) -> dict[str, object]:
    """All grid-stage figures as plain data."""
    truth = read_truth(truth_path)
    opening = min_opening_deg if min_opening_deg is not None else DoorbatchConfig().doors.min_opening_deg
    tset, moved = truth_doors(truth, math.radians(opening))
    det = read_door_set(map_dir)
    s = score_doors(det, tset, moved)
    static = score_static_occupancy(read_map(map_dir / "map.yaml"),
                                    read_map(truth_path.parent / truth.files["map_static"]))
    return {
        "doors_detected": len(det), "doors_moved_in_truth": int(moved.sum()), "precision": s.precision,
        "recall": s.recall, "false_positives": [[round(float(v), 2) for v in det.hinge[i]] for i in s.false_positives],
        "missed": [truth.doors[j].name for j in s.missed],
        "hinge_error_max_m": float(s.hinge_error_m.max()) if s.matches else None,
        "length_error_max_m": float(np.abs(s.length_error_m).max()) if s.matches else None,
        "range_error_max_deg": float(np.degrees(s.range_error_rad.max())) if s.matches else None,
        "static_agreement": static.agreement, "observed_cells": static.observed_cells,
        "spurious_occupied_cells": static.spurious_occupied_cells,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("map_dir", type=Path)
    parser.add_argument("truth", type=Path)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    result = score(args.map_dir, args.truth)
    print(json.dumps(result, indent=2) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items()))


if __name__ == "__main__":
    main()
