"""Issue #4 acceptance of the grid stage on simulated logs: doors, opening ranges, static map, people.

For each site: simulate it (``mapping_pass`` scenario, one log per pass) unless its logs are there
already, run ``build_map`` (reference poses), and score the result against the simulator's truth with
``doorbatch.pipeline.evaluate.door_map``. Prints one table.

Usage::

    python scripts/gridmap_acceptance.py [--work DIR] [--site WORLD:SEED ...] [--set section.key=value ...] [--json]

Sites: the bundled sample (``datasets/sample``, office_corridor seed 1) and office_corridor seed 2,
l_corridor seed 3, double_door seed 4; ``--site`` replaces the simulated ones (e.g.
``--site l_corridor:11``). Without ``--work`` the simulated logs go to a temporary folder that is removed.

Columns: doors the laser saw at two or more distinguishable angles (truth ``leaf_observations``), doors
found among them, precision and recall (a detection matched to a door that never moved counts as a false
positive), the largest hinge / leaf length / opening-range errors of the matches, the static map's
agreement with the door-less truth map on observed cells, and the occupied cells of the static map with
no truth wall within a cell: all of them, those outside every door's swept sector (the rest are leaves of
doors that never moved, the EM stage's job), and those on a walking person's path (radius + 0.1 m).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.ndimage import maximum_filter

from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.map_server import read_map
from doorbatch.io.sim_truth import SimTruth, read_truth
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.evaluate.door_map import resample_onto, score_doors, score_static_map, truth_doors
from doorbatch.pipeline.mapping import build_map
from doorbatch.sim.simulate import run_simulation

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SITES = ("office_corridor:2", "l_corridor:3", "double_door:4")


@dataclass(frozen=True)
class Site:
    """A mapping run: its pass logs and truth file."""

    name: str
    logs: list[Path]
    truth: Path


def sample_site() -> Site:
    logs = ROOT / "datasets" / "sample" / "logs"
    return Site("sample (office_corridor:1)", sorted(logs.glob("map_pass*.mcap")), logs / "map.truth.yaml")


def simulated_site(spec: str, work: Path) -> Site:
    """Simulate WORLD:SEED with the mapping_pass scenario into ``work`` (unless it is there already)."""
    world, _, seed = spec.partition(":")
    folder = work / f"{world}_seed{seed}"
    truth = folder / "map.truth.yaml"
    if not truth.exists() or not sorted(folder.glob("map_pass*.mcap")):
        run_simulation(ROOT / "configs" / "worlds" / f"{world}.yaml", folder / "map.mcap", scenario="mapping_pass",
                       seed=int(seed), split_passes=True)
        (folder / "map.mcap").unlink(missing_ok=True)  # the passes are what doorbatch map takes
    return Site(spec, sorted(folder.glob("map_pass*.mcap")), truth)


def door_sectors(truth: SimTruth, grid: OccupancyMap, margin_m: float) -> np.ndarray:
    """Cells whose centre lies within ``margin_m`` of the sector each truth door can sweep (0 … its
    maximum opening angle, radius = leaf length)."""
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    xy = grid.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=1)).reshape(grid.height, grid.width, 2)
    mask = np.zeros((grid.height, grid.width), dtype=bool)
    for d in truth.doors:
        dx, dy = xy[..., 0] - d.hinge_x, xy[..., 1] - d.hinge_y
        r = np.hypot(dx, dy)
        rel = d.opening_sign * wrap_angle(np.arctan2(dy, dx) - d.closed_yaw)  # opening angle of the cell
        slack = np.arcsin(np.minimum(1.0, margin_m / np.maximum(r, margin_m)))  # the margin as an angle
        mask |= ((r <= d.length + margin_m) & (rel >= -slack) & (rel <= d.max_angle + slack)) | (r <= margin_m)
    return mask


def people_corridors(truth: SimTruth, grid: OccupancyMap, margin_m: float) -> np.ndarray:
    """Cells whose centre lies within a person's radius + ``margin_m`` of their walking path."""
    rows, cols = np.mgrid[0:grid.height, 0:grid.width]
    xy = grid.cell_to_world(np.stack([rows.ravel(), cols.ravel()], axis=1))
    mask = np.zeros(xy.shape[0], dtype=bool)
    for person in truth.people:
        path = np.asarray(person["path"], dtype=np.float64).reshape(-1, 2)
        for a, b in itertools.pairwise(path):
            t = np.clip((xy - a) @ (b - a) / max(float((b - a) @ (b - a)), 1e-12), 0.0, 1.0)
            mask |= np.hypot(*(xy - (a + t[:, None] * (b - a))).T) <= float(person["radius"]) + margin_m
    return mask.reshape(grid.height, grid.width)


def evaluate(site: Site, config: DoorbatchConfig) -> dict[str, object]:
    """Map one site and score it."""
    result = build_map(site.logs, config)
    truth = read_truth(site.truth)
    tset, moved = truth_doors(truth, math.radians(config.doors.min_opening_deg))
    doors = result.doors
    det = DoorSet(np.array([[d.hinge_x, d.hinge_y] for d in doors], dtype=float).reshape(-1, 2),
                  np.array([d.length for d in doors]), np.array([d.closed_yaw for d in doors]),
                  np.array([d.angle_min for d in doors]), np.array([d.angle_max for d in doors]))
    s = score_doors(det, tset, moved)
    est = result.static_map
    truth_map = resample_onto(read_map(site.truth.parent / truth.files["map_static"]), est)
    static = score_static_map(est.occupancy, truth_map)
    spurious = (est.occupancy >= 65) & ~maximum_filter(truth_map >= 65, size=3)
    off_doors = spurious & ~door_sectors(truth, est, 0.15)
    on_paths = spurious & people_corridors(truth, est, 0.1)
    return {
        "site": site.name, "passes": len(site.logs), "doors_moved": int(moved.sum()), "found": len(s.matches),
        "detected": len(doors), "precision": s.precision, "recall": s.recall,
        "missed": [truth.doors[j].name for j in s.missed],
        "false_positives": [[round(float(v), 2) for v in det.hinge[i]] for i in s.false_positives],
        "hinge_error_max_m": float(s.hinge_error_m.max()) if s.matches else None,
        "length_error_max_m": float(np.abs(s.length_error_m).max()) if s.matches else None,
        "range_error_max_deg": float(np.degrees(s.range_error_rad.max())) if s.matches else None,
        "static_agreement": static.agreement, "spurious_occupied_cells": static.spurious_occupied_cells,
        "spurious_off_door_sectors": int(off_doors.sum()), "spurious_on_people_paths": int(on_paths.sum()),
        "grid_seconds": result.stage_seconds.get("grid"),
    }


def _fmt(v: object, digits: int) -> str:
    return "—" if v is None else f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def table(rows: list[dict[str, object]]) -> str:
    """The results as a Markdown table."""
    head = ("| site | doors seen moved | found | precision | recall | max hinge err (m) | max length err (m) "
            "| max range err (°) | static agreement | spurious occupied cells: all (off door sectors) "
            "[on people's paths] |")
    lines = [head, "|" + "---|" * 10]
    for r in rows:
        lines.append(
            f"| {r['site']} | {r['doors_moved']} | {r['found']} | {_fmt(r['precision'], 2)} | {_fmt(r['recall'], 2)} "
            f"| {_fmt(r['hinge_error_max_m'], 3)} | {_fmt(r['length_error_max_m'], 3)} "
            f"| {_fmt(r['range_error_max_deg'], 1)} | {100 * float(r['static_agreement']):.2f}% "  # type: ignore[arg-type]
            f"| {r['spurious_occupied_cells']} ({r['spurious_off_door_sectors']}) [{r['spurious_on_people_paths']}] |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, help="folder for the simulated logs (kept; reused when present)")
    parser.add_argument("--site", action="append", help="WORLD:SEED to simulate instead of the default three")
    parser.add_argument("--json", action="store_true", help="print the results as JSON")
    parser.add_argument("--set", action="append", default=[], dest="sets", help="config override, section.key=value")
    args = parser.parse_args()
    config = load_config(None, args.sets)
    specs = args.site or list(DEFAULT_SITES)
    with tempfile.TemporaryDirectory(prefix="gridmap_acceptance_") as tmp:
        work = args.work or Path(tmp)
        sites = [sample_site(), *(simulated_site(spec, work) for spec in specs)]
        rows = [evaluate(site, config) for site in sites]
    if args.json:
        print(json.dumps(rows, indent=2))
        return
    print(table(rows))
    for r in rows:
        if r["missed"] or r["false_positives"]:
            print(f"{r['site']}: missed {r['missed']}, false positives at {r['false_positives']}")


if __name__ == "__main__":
    main()
