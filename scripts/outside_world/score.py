#!/usr/bin/env python3
"""Score doorbatch outputs against the outside-world simulator's truth (``scripts/outside_world/gen.py``).

``map MAPDIR``: a ``doorbatch map`` directory (doors.parquet, map.yaml + map.pgm) against the mapping
passes it was built from (read from MAPDIR/manifest.json, or ``--passes``):

(a) doors: for each true door the nearest mapped hinge (within 0.5 m): hinge error, leaf length error,
    and the mapped opening range expressed in the true door's closed frame (degrees CCW from the true
    closed direction) next to the range the passes really showed; mapped doors matching no true door
    are false doors. A door at the same angle in every pass (D) is a wall to the mapper, not a door.
(b) static map: share of occupied cells within 0.075 m of a true static wall (static walls plus the
    leaves of doors that never move), share of the observed true walls (sampled every 2 cm) with an
    occupied cell within one cell, occupied cells on the person's path (within the person's radius
    plus one cell of its recorded track) and in the corridor interior.
(c) leaf remnants: for each moving door and each angle it had in a pass, occupied cells on that true
    leaf more than 0.15 m from the hinge and more than 0.06 m off any static wall.

``run RUNDIR LOGNAME``: a ``doorbatch localize`` directory (trajectory.parquet, door_states.parquet)
against LOGNAME's truth: (d) APE (no alignment: the map is built in the true world frame from
/ground_truth) mean / RMSE / max, and per door the error of the estimated leaf direction in the world
frame (the map door's closed_yaw + estimated angle, against the true closed_yaw + sign · true angle).
The map's doors are read from the run's manifest (or ``--map``).

``--world DIR`` is gen.py's ``--out`` folder (default /tmp/outside_world). The world's geometry comes
from gen.py beside this file; nothing is imported from doorbatch (run this file as a script).
"""

from __future__ import annotations

import argparse
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow.parquet as pq
import yaml
from gen import DEFAULT_OUT, DOORS, LEAF_M, PERSON_RADIUS_M, leaf_segments, static_segments
from numpy.typing import NDArray
from PIL import Image
from scipy.spatial import cKDTree

FloatArray = NDArray[np.float64]

OCCUPIED, UNKNOWN = 0, 205  # map.pgm values (trinary)
DOOR_MATCH_M = 0.5  # a mapped hinge this close to a true hinge is that door
WALL_TOLERANCE_M = 0.075  # an occupied cell this close to a true wall is on it
WALL_SAMPLE_STEP_M = 0.02
LEAF_TOLERANCE_M = 0.04  # a cell this close to a true leaf is on it
OFF_WALL_M = 0.06  # ... and this far from static walls is not explained by them
HINGE_EXCLUSION_M = 0.15  # cells this close to the hinge are the hinge, not a remnant
CORRIDOR_INTERIOR = (0.3, 29.7, 6.15, 7.85)  # x0, x1, y0, y1 (m)
APE_OUTLIER_M = 0.15


# ---------------------------------------------------------------- inputs
@dataclass
class LogTruth:
    """One simulated log's truth: door angles (deg, opening into the room), true poses, person track."""

    name: str
    door_angles_deg: dict[str, float]
    tum: FloatArray  # (N, 8): t_s, x, y, z, qx, qy, qz, qw
    person_track: FloatArray | None  # (M, 3): t_s, x, y at each scan, None without a person


def load_truth(world: Path, name: str) -> LogTruth:
    """Truth files of log ``name`` under gen.py's output folder ``world``."""
    truth_dir = world / "truth"
    meta = json.loads((truth_dir / f"{name}.json").read_text())
    person_path = truth_dir / f"{name}.person.npy"
    person = np.load(person_path) if person_path.exists() else None
    return LogTruth(name, meta["door_angles_deg"], np.loadtxt(truth_dir / f"{name}.tum"), person)


@dataclass
class OccupancyMap:
    """A map_server trinary map: the PGM image (row 0 at the top), cell size and lower-left origin."""

    image: NDArray[np.uint8]
    resolution_m: float
    origin_xy: tuple[float, float]

    def cell_centres(self, mask: NDArray[np.bool_]) -> FloatArray:
        """World (x, y) centres (N, 2) of the cells where ``mask`` (image-shaped) is true."""
        rows, cols = np.nonzero(mask)
        n_rows = self.image.shape[0]
        x = self.origin_xy[0] + (cols + 0.5) * self.resolution_m
        y = self.origin_xy[1] + (n_rows - 1 - rows + 0.5) * self.resolution_m
        return np.column_stack([x, y]).astype(np.float64)

    def occupied_centres(self) -> FloatArray:
        """World centres of the occupied cells."""
        return self.cell_centres(self.image == OCCUPIED)

    def cells_of(self, points: FloatArray) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Image (row, col) of the cells holding world ``points`` (N, 2); may fall outside the image."""
        cols = np.floor((points[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(np.int64)
        rows = self.image.shape[0] - 1 - np.floor((points[:, 1] - self.origin_xy[1]) / self.resolution_m).astype(
            np.int64)
        return rows, cols


def read_map(map_dir: Path) -> OccupancyMap:
    """MAPDIR/map.yaml and its image."""
    meta = yaml.safe_load((map_dir / "map.yaml").read_text())
    image = np.array(Image.open(map_dir / meta["image"]))
    return OccupancyMap(image, float(meta["resolution"]), (float(meta["origin"][0]), float(meta["origin"][1])))


def read_table(path: Path) -> dict[str, NDArray[Any]]:
    """A parquet file as a dict of numpy columns."""
    return {k: np.asarray(v) for k, v in pq.read_table(path).to_pydict().items()}


def manifest_inputs(out_dir: Path) -> list[Path]:
    """Input paths recorded in a doorbatch output's manifest.json (empty if there is none)."""
    manifest = out_dir / "manifest.json"
    if not manifest.exists():
        return []
    return [Path(i["path"]) for i in json.loads(manifest.read_text()).get("inputs", [])]


def map_pass_names(map_dir: Path, world: Path, passes: list[str] | None) -> list[str]:
    """Names of the logs the map was built from: ``passes``, else the manifest's inputs that have truth."""
    if passes:
        return passes
    names = [p.name for p in manifest_inputs(map_dir) if (world / "truth" / f"{p.name}.json").exists()]
    return names or ["pass1", "pass2", "pass3"]


# ---------------------------------------------------------------- geometry
def wrap_rad(a: Any) -> Any:
    """Angle(s) wrapped to [-π, π)."""
    return (a + math.pi) % (2 * math.pi) - math.pi


def point_segment_distance_m(points: FloatArray, segs: FloatArray) -> FloatArray:
    """Distance (N,) from each point (N, 2) to the nearest segment of ``segs`` (M, 4)."""
    a, b = segs[:, :2], segs[:, 2:]
    ab = b - a
    ap = points[:, None, :] - a[None]
    t = np.clip((ap * ab[None]).sum(-1) / np.maximum((ab**2).sum(-1), 1e-12)[None], 0, 1)
    nearest = a[None] + t[..., None] * ab[None]
    d: FloatArray = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)).min(1)
    return d


def sample_segments(segs: FloatArray, step_m: float) -> FloatArray:
    """Points (N, 2) along every segment, about ``step_m`` apart, ends included."""
    pts = []
    for x0, y0, x1, y1 in segs:
        n = max(2, int(math.hypot(x1 - x0, y1 - y0) / step_m))
        t = np.linspace(0, 1, n)
        pts.append(np.c_[x0 + t * (x1 - x0), y0 + t * (y1 - y0)])
    return np.concatenate(pts)


def door_angles_over_passes(passes: list[LogTruth]) -> dict[str, list[float]]:
    """Each door's angle (deg, opening into the room) in each pass."""
    return {k: [p.door_angles_deg[k] for p in passes] for k in DOORS}


def static_truth_walls(passes: list[LogTruth]) -> FloatArray:
    """True walls of the mapped world: static walls plus the leaves of doors at one angle in every pass."""
    leaves = [leaf_segments(k, a[0]) for k, a in door_angles_over_passes(passes).items() if len(set(a)) == 1]
    return np.concatenate([static_segments(), *leaves])


# ---------------------------------------------------------------- (a) doors of the map
def true_range_ccw_deg(name: str, angles_deg: list[float]) -> tuple[float, float]:
    """The range of leaf directions the passes showed, in degrees CCW from the true closed direction."""
    ccw = [DOORS[name]["sign"] * a for a in angles_deg]
    return min(ccw), max(ccw)


def mapped_range_in_true_frame_deg(closed_yaw_rad: float, angle_min_rad: float, angle_max_rad: float,
                                   true_closed_yaw_rad: float) -> tuple[float, float]:
    """A mapped door's opening range re-expressed in degrees CCW from the true closed direction."""
    off = wrap_rad(closed_yaw_rad - true_closed_yaw_rad)
    ends = sorted(math.degrees(wrap_rad(off + a)) for a in (angle_min_rad, angle_max_rad))
    return ends[0], ends[1]


def nearest_door_row(doors: dict[str, NDArray[Any]], hinge_xy: tuple[float, float],
                     exclude: set[int]) -> tuple[int | None, float]:
    """Row of the mapped door whose hinge is nearest ``hinge_xy`` (not in ``exclude``), and its distance."""
    if len(doors["door_id"]) == 0:
        return None, math.inf
    dist = np.hypot(doors["hinge_x"] - hinge_xy[0], doors["hinge_y"] - hinge_xy[1])
    dist[list(exclude)] = np.inf
    j = int(dist.argmin())
    return (j, float(dist[j])) if np.isfinite(dist[j]) else (None, math.inf)


def score_door_map(doors: dict[str, NDArray[Any]], passes: list[LogTruth]) -> dict[str, Any]:
    """(a) Per true door: match, hinge / length errors, true and mapped opening ranges; and the false doors."""
    angles = door_angles_over_passes(passes)
    used: set[int] = set()
    rows = []
    for name, door in DOORS.items():
        row: dict[str, Any] = {"door": name, "moves": len(set(angles[name])) > 1,
                               "true_range_ccw_deg": true_range_ccw_deg(name, angles[name])}
        row["nearest_m"] = nearest_door_row(doors, door["hinge"], set())[1]
        j, dist = nearest_door_row(doors, door["hinge"], used)
        if j is not None and dist <= DOOR_MATCH_M:
            used.add(j)
            lo, hi = mapped_range_in_true_frame_deg(doors["closed_yaw"][j], doors["angle_min"][j],
                                                    doors["angle_max"][j], door["closed_yaw"])
            tr = row["true_range_ccw_deg"]
            row.update(door_id=int(doors["door_id"][j]), hinge_error_m=dist,
                       length_error_m=float(doors["length"][j]) - LEAF_M, mapped_range_ccw_deg=(lo, hi),
                       range_error_deg=(lo - tr[0], hi - tr[1]),
                       closed_yaw_diff_deg=math.degrees(wrap_rad(doors["closed_yaw"][j] - door["closed_yaw"])),
                       source=str(doors["source"][j]), moved=bool(doors["moved"][j]),
                       n_observations=int(doors["n_observations"][j]))
        rows.append(row)
    false_doors = [{"door_id": int(doors["door_id"][j]), "hinge": (float(doors["hinge_x"][j]),
                                                                   float(doors["hinge_y"][j])),
                    "length_m": float(doors["length"][j])}
                   for j in range(len(doors["door_id"])) if j not in used]
    return {"doors": rows, "false_doors": false_doors}


# ---------------------------------------------------------------- (b) static map
def wall_precision(occupied: FloatArray, walls: FloatArray) -> dict[str, Any]:
    """Share of occupied cells within WALL_TOLERANCE_M of a true wall, and the worst offenders."""
    d = point_segment_distance_m(occupied, walls) if len(occupied) else np.zeros(0)
    off = occupied[d >= WALL_TOLERANCE_M]
    return {"occupied_cells": len(occupied), "on_true_wall_share": float((d < WALL_TOLERANCE_M).mean()),
            "off_wall_cells": len(off), "off_wall_examples": np.round(off[:20], 2).tolist()}


def wall_recall(grid: OccupancyMap, walls: FloatArray) -> dict[str, Any]:
    """Share of true wall samples in the observed area (a known cell in their 3×3 neighbourhood) with an
    occupied cell in that neighbourhood."""
    rows, cols = grid.cells_of(sample_segments(walls, WALL_SAMPLE_STEP_M))
    n_rows, n_cols = grid.image.shape
    inside = (cols >= 1) & (cols < n_cols - 1) & (rows >= 1) & (rows < n_rows - 1)
    rows, cols = rows[inside], cols[inside]
    nb = np.stack([grid.image[rows + dr, cols + dc] for dr in (-1, 0, 1) for dc in (-1, 0, 1)], 1)
    observed = (nb != UNKNOWN).any(1)
    hit = (nb == OCCUPIED).any(1)
    return {"observed_wall_samples": int(observed.sum()),
            "observed_wall_hit_share": float(hit[observed].mean()) if observed.any() else math.nan}


def cells_on_person_path(occupied: FloatArray, grid: OccupancyMap, passes: list[LogTruth]) -> dict[str, Any]:
    """Occupied cells within the person's radius plus one cell of its track in the passes, and in the
    corridor interior (anything there is clutter the static map should not have)."""
    tracks = [p.person_track[:, 1:3] for p in passes if p.person_track is not None]
    on_path = np.zeros(len(occupied), bool)
    if tracks and len(occupied):
        d, _ = cKDTree(np.concatenate(tracks)).query(occupied)
        on_path = d <= PERSON_RADIUS_M + grid.resolution_m
    x0, x1, y0, y1 = CORRIDOR_INTERIOR
    inside = ((occupied[:, 0] > x0) & (occupied[:, 0] < x1) & (occupied[:, 1] > y0) & (occupied[:, 1] < y1))
    return {"person_path_cells": int(on_path.sum()),
            "person_path_examples": np.round(occupied[on_path][:10], 2).tolist(),
            "corridor_interior_cells": int(inside.sum()),
            "corridor_interior_examples": np.round(occupied[inside][:10], 2).tolist()}


# ---------------------------------------------------------------- (c) leaf remnants
def leaf_remnants(occupied: FloatArray, passes: list[LogTruth]) -> list[dict[str, Any]]:
    """For each moving door and each of its pass angles: occupied cells on that true leaf, beyond
    HINGE_EXCLUSION_M of the hinge and OFF_WALL_M off the static walls, and how far out they reach."""
    off_walls = point_segment_distance_m(occupied, static_truth_walls(passes)) > OFF_WALL_M
    out = []
    for name, angles in door_angles_over_passes(passes).items():
        if len(set(angles)) == 1:
            continue
        hx, hy = DOORS[name]["hinge"]
        from_hinge = np.hypot(occupied[:, 0] - hx, occupied[:, 1] - hy)
        for angle in sorted(set(angles)):
            on_leaf = point_segment_distance_m(occupied, leaf_segments(name, angle)) < LEAF_TOLERANCE_M
            m = on_leaf & off_walls & (from_hinge > HINGE_EXCLUSION_M)
            out.append({"door": name, "angle_deg": angle, "cells": int(m.sum()),
                        "max_from_hinge_m": float(from_hinge[m].max()) if m.any() else 0.0})
    return out


def score_map(map_dir: Path, world: Path, pass_names: list[str] | None) -> dict[str, Any]:
    """(a)-(c) for a doorbatch map directory."""
    passes = [load_truth(world, n) for n in map_pass_names(map_dir, world, pass_names)]
    grid = read_map(map_dir)
    occupied = grid.occupied_centres()
    walls = static_truth_walls(passes)
    return {"map": str(map_dir), "passes": [p.name for p in passes],
            **score_door_map(read_table(map_dir / "doors.parquet"), passes),
            "static": {**wall_precision(occupied, walls), **wall_recall(grid, walls),
                       **cells_on_person_path(occupied, grid, passes)},
            "leaf_remnants": leaf_remnants(occupied, passes)}


# ---------------------------------------------------------------- (d) localization run
def true_poses_at(truth: LogTruth, t_s: FloatArray) -> FloatArray:
    """True (x, y, yaw) (N, 3) at times ``t_s``, interpolated (yaw unwrapped, then wrapped)."""
    tum = truth.tum
    yaw = np.unwrap(2 * np.arctan2(tum[:, 6], tum[:, 7]))
    columns = [np.interp(t_s, tum[:, 0], tum[:, 1]), np.interp(t_s, tum[:, 0], tum[:, 2]),
               wrap_rad(np.interp(t_s, tum[:, 0], yaw))]
    return np.column_stack(columns).astype(np.float64)


def rows_of_log(table: dict[str, NDArray[Any]], log: str) -> dict[str, NDArray[Any]]:
    """The rows of a doorbatch table that belong to ``log`` (all rows if no row names it)."""
    if "log" not in table or not (table["log"] == log).any():
        return table
    keep = table["log"] == log
    return {k: v[keep] for k, v in table.items()}


def absolute_pose_error(traj: dict[str, NDArray[Any]], truth: LogTruth) -> dict[str, Any]:
    """APE of the estimated positions against the interpolated truth (world frame, no alignment)."""
    t_s = traj["stamp_ns"] / 1e9
    true = true_poses_at(truth, t_s)
    e = np.hypot(traj["x"] - true[:, 0], traj["y"] - true[:, 1])
    yaw_err = np.degrees(np.abs(wrap_rad(traj["yaw"] - true[:, 2])))
    return {"n": len(e), "mean_m": float(e.mean()), "rmse_m": float(np.sqrt((e**2).mean())), "max_m": float(e.max()),
            "t_max_s": float(t_s[e.argmax()] - truth.tum[0, 0]), "n_over_outlier": int((e > APE_OUTLIER_M).sum()),
            "yaw_mean_deg": float(yaw_err.mean()), "yaw_max_deg": float(yaw_err.max())}


def door_angle_errors(doors: dict[str, NDArray[Any]], states: dict[str, NDArray[Any]],
                      truth: LogTruth) -> list[dict[str, Any]]:
    """Per map door: the world-frame error (deg, CCW) of the estimated leaf direction (map closed_yaw +
    angle) against the true one, at the last state and over the rows where the door was observed."""
    out = []
    for j in range(len(doors["door_id"])):
        name = min(DOORS, key=lambda n: math.hypot(DOORS[n]["hinge"][0] - doors["hinge_x"][j],
                                                    DOORS[n]["hinge"][1] - doors["hinge_y"][j]))
        door = DOORS[name]
        dist = math.hypot(door["hinge"][0] - doors["hinge_x"][j], door["hinge"][1] - doors["hinge_y"][j])
        row: dict[str, Any] = {"door_id": int(doors["door_id"][j]), "door": name if dist <= DOOR_MATCH_M else None,
                               "hinge_distance_m": dist}
        s = states["door_id"] == doors["door_id"][j]
        if row["door"] is None or not s.any():
            out.append(row)
            continue
        true_deg = truth.door_angles_deg[name]
        true_abs = door["closed_yaw"] + door["sign"] * math.radians(true_deg)
        est_abs = doors["closed_yaw"][j] + states["angle"][s]
        err = np.degrees(wrap_rad(est_abs - true_abs))
        observed = states["observed"][s].astype(bool)
        row.update(true_deg=true_deg,
                   final_est_deg=door["sign"] * math.degrees(wrap_rad(est_abs[-1] - door["closed_yaw"])),
                   final_err_deg=float(err[-1]), final_std_deg=math.degrees(states["angle_std"][s][-1]),
                   observed_rows=int(observed.sum()), rows=int(s.sum()),
                   observed_median_abs_err_deg=float(np.median(np.abs(err[observed]))) if observed.any() else math.nan,
                   observed_max_abs_err_deg=float(np.abs(err[observed]).max()) if observed.any() else math.nan)
        out.append(row)
    return out


def run_doors_path(run_dir: Path, map_dir: Path | None) -> Path:
    """doors.parquet of the map the run used: ``--map``'s, else the one in the run's manifest."""
    if map_dir is not None:
        return map_dir / "doors.parquet"
    for p in manifest_inputs(run_dir):
        if p.name == "doors.parquet":
            return p
    raise SystemExit(f"{run_dir}/manifest.json names no doors.parquet: pass --map MAPDIR")


def score_run(run_dir: Path, log: str, world: Path, map_dir: Path | None) -> dict[str, Any]:
    """(d) for a doorbatch localize directory."""
    truth = load_truth(world, log)
    traj = rows_of_log(read_table(run_dir / "trajectory.parquet"), log)
    result: dict[str, Any] = {"run": str(run_dir), "log": log, "ape": absolute_pose_error(traj, truth)}
    states_path = run_dir / "door_states.parquet"
    states = rows_of_log(read_table(states_path), log) if states_path.exists() else {}
    if states and len(states["door_id"]):
        result["doors"] = door_angle_errors(read_table(run_doors_path(run_dir, map_dir)), states, truth)
    else:
        result["doors"] = []
    return result


# ---------------------------------------------------------------- printing
def fmt_pair(p: tuple[float, float], spec: str = ".1f") -> str:
    """(a, b) with both numbers formatted by ``spec``."""
    return f"({p[0]:{spec}}, {p[1]:{spec}})"


def print_map_report(r: dict[str, Any]) -> None:
    """Human-readable (a)-(c)."""
    print(f"map {r['map']}  passes {', '.join(r['passes'])}")
    print("(a) doors (ranges: degrees CCW from the true closed direction)")
    for d in r["doors"]:
        head = f"  {d['door']}: true range {fmt_pair(d['true_range_ccw_deg'])}"
        if not d["moves"]:
            head += " (same angle in every pass: a wall to the mapper)"
        if "door_id" not in d:
            why = "" if d["nearest_m"] > DOOR_MATCH_M else ", matched to another door"
            print(f"{head}  not mapped (nearest mapped hinge {d['nearest_m']:.2f} m{why})")
            continue
        print(f"{head}  id {d['door_id']}: hinge err {d['hinge_error_m']:.3f} m, length err "
              f"{d['length_error_m']:+.3f} m, mapped range {fmt_pair(d['mapped_range_ccw_deg'])}, range err "
              f"{fmt_pair(d['range_error_deg'], '+.1f')}, closed_yaw diff {d['closed_yaw_diff_deg']:.1f}°, "
              f"source {d['source']}, moved {d['moved']}, n_obs {d['n_observations']}")
    print(f"  false doors: {len(r['false_doors'])}")
    for f in r["false_doors"]:
        print(f"    id {f['door_id']} hinge {fmt_pair(f['hinge'], '.2f')} length {f['length_m']:.2f} m")
    s = r["static"]
    print("(b) static map")
    print(f"  occupied cells {s['occupied_cells']}, within {WALL_TOLERANCE_M} m of a true wall: "
          f"{100 * s['on_true_wall_share']:.1f}% ({s['off_wall_cells']} off)")
    if s["off_wall_cells"]:
        print(f"    e.g. {s['off_wall_examples']}")
    print(f"  observed true wall samples {s['observed_wall_samples']}, with an occupied cell within one cell: "
          f"{100 * s['observed_wall_hit_share']:.1f}%")
    print(f"  occupied cells on the person's path: {s['person_path_cells']} {s['person_path_examples']}")
    print(f"  occupied cells in the corridor interior: {s['corridor_interior_cells']} "
          f"{s['corridor_interior_examples']}")
    print(f"(c) leaf remnants (cells on the true leaf, > {HINGE_EXCLUSION_M} m from the hinge, off walls)")
    for x in r["leaf_remnants"]:
        print(f"  door {x['door']} at {x['angle_deg']}°: {x['cells']} cells, up to {x['max_from_hinge_m']:.2f} m "
              "from the hinge")


def print_run_report(r: dict[str, Any]) -> None:
    """Human-readable (d)."""
    a = r["ape"]
    print(f"run {r['run']}  log {r['log']}")
    print(f"(d) APE n={a['n']} mean={a['mean_m']:.4f} m rmse={a['rmse_m']:.4f} m max={a['max_m']:.4f} m "
          f"(at {a['t_max_s']:.1f} s), > {APE_OUTLIER_M} m: {a['n_over_outlier']}; "
          f"yaw mean {a['yaw_mean_deg']:.2f}° max {a['yaw_max_deg']:.2f}°")
    if not r["doors"]:
        print("  no door states")
    for d in r["doors"]:
        if "true_deg" not in d:
            print(f"  map door {d['door_id']}: no true door within {DOOR_MATCH_M} m "
                  f"(nearest {d['hinge_distance_m']:.2f} m) or no states")
            continue
        print(f"  door {d['door']} (map id {d['door_id']}): true {d['true_deg']}°, final est {d['final_est_deg']:.1f}° "
              f"(err CCW {d['final_err_deg']:+.1f}°, std {d['final_std_deg']:.1f}°), observed rows "
              f"{d['observed_rows']}/{d['rows']}, |err| observed median {d['observed_median_abs_err_deg']:.1f}° "
              f"max {d['observed_max_abs_err_deg']:.1f}°")


def main() -> None:
    """Command line: ``map MAPDIR`` or ``run RUNDIR LOGNAME``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    pm = sub.add_parser("map", help="score a doorbatch map directory")
    pm.add_argument("map_dir", type=Path)
    pm.add_argument("--passes", nargs="+", metavar="NAME", help="mapping logs (default: from the manifest)")
    pr = sub.add_parser("run", help="score a doorbatch localize directory")
    pr.add_argument("run_dir", type=Path)
    pr.add_argument("log", help="the localized log's name (its truth files)")
    pr.add_argument("--map", type=Path, dest="map_dir", help="map directory (default: from the run's manifest)")
    for p in (pm, pr):
        p.add_argument("--world", type=Path, default=DEFAULT_OUT, help=f"gen.py's --out (default {DEFAULT_OUT})")
        p.add_argument("--json", action="store_true", help="print the figures as JSON")
    args = parser.parse_args()
    if args.command == "map":
        result = score_map(args.map_dir, args.world, args.passes)
        printer = print_map_report
    else:
        result = score_run(args.run_dir, args.log, args.world, args.map_dir)
        printer = print_run_report
    if args.json:
        print(json.dumps(result, indent=1, default=float))
    else:
        printer(result)


if __name__ == "__main__":
    main()
