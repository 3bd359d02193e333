"""MCL and RBPF tracking on the real CARMEN logs (issue #5): ATE against the corrected poses.

The logs in ``../shared/datasets/carmen/`` are corrected logs: their odometry equals the corrected poses
(DESIGN.md). For each log:

1. map from the corrected poses: ``doorbatch map LOG --pose-source reference -o WORK/<name>/map``;
2. odometry replaced by the corrected poses at the scan stamps corrupted with the simulator's drift model
   (the default scenario's odometry noise at its 50 Hz odometry resolution,
   :func:`doorbatch.sim.simulate.scenario_drift`, seed ``--seed``), as
   ``scripts/scanmatch_acceptance.py`` does; it starts at the first corrected pose;
3. ``localize`` with ``--init reference`` (first corrected pose), MCL and RBPF, the default config
   (``--set`` overrides it);
4. ATE (translational RMSE, no alignment: the map is in the corrected poses' frame) and the maximum position
   error at the filter's updates, against the corrected poses; the same for the corrupted odometry.

The logs hold only the scans of the corrected trajectory (237 / 910 / 440 scans, 0.5–1 m apart), so every
scan is used; no window or decimation.

Usage: ``python scripts/localize_carmen.py [--work DIR] [--seed N] [--filter-seed N] [--logs orebro intel aces]
[--config FILE] [--set localize.KEY=VALUE ...] [--init global]`` (``--config``: as ``doorbatch --config``, a Nav2
parameter file too; ``--init global``: a uniform start, with the convergence time, ambiguity and final error).
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np

from doorbatch.cli import main as cli_main
from doorbatch.config import load_config
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import PoseSeries, Recording, load_recording
from doorbatch.pipeline.evaluate.trajectory_error import ate_rmse, position_errors
from doorbatch.pipeline.localize.run import load_localization_map, localize_recording
from doorbatch.sim.scenario import load_scenario
from doorbatch.sim.simulate import scenario_drift

REPO = Path(__file__).resolve().parents[1]
CARMEN = REPO.parent / "shared" / "datasets" / "carmen"


def drifting_odometry(ref: np.ndarray, seed: int) -> np.ndarray:
    """Corrected poses (N, 3) corrupted with the default scenario's drift model (the simulator's odometry, at
    its odometry stream's resolution)."""
    return scenario_drift(ref, load_scenario(None), np.random.default_rng(seed))


def with_drifting_odometry(rec: Recording, seed: int) -> tuple[Recording, np.ndarray]:
    """The recording with its odometry replaced by the corrected poses at the scan stamps, corrupted with the
    default scenario's drift model; and those corrected poses (the reference at the scans)."""
    assert rec.reference is not None
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns)
    if not ok.all():
        raise SystemExit(f"{rec.path}: {int((~ok).sum())} scans without a corrected pose")
    series = PoseSeries(rec.scans.stamps_ns.copy(), drifting_odometry(ref, seed), "odom")
    return dataclasses.replace(rec, odometry=series), ref


def evaluate(name: str, work: Path, seed: int, filter_seed: int, overrides: list[str], config_file: Path | None = None,
             init: str = "reference") -> list[dict[str, object]]:
    """One row per method (and one for the corrupted odometry) for the log ``name``."""
    log = CARMEN / f"{name}-corrected.log.gz"
    map_dir = work / name / "map"
    if not (map_dir / "map.yaml").exists():
        assert cli_main(["map", str(log), "--pose-source", "reference", "-o", str(map_dir), "-q"]) == 0
    config = load_config(config_file, [*overrides, f"seed={filter_seed}"])
    rec, ref = with_drifting_odometry(load_recording(log, config), seed)
    lmap = load_localization_map(map_dir, config.localize)
    assert rec.odometry is not None
    rows: list[dict[str, object]] = [{"log": name, "method": "odom (drift)", "updates": len(ref),
                                      "ate_m": ate_rmse(rec.odometry.poses, ref),
                                      "max_m": float(position_errors(rec.odometry.poses, ref).max()),
                                      "first_over_1m": None, "doors": len(lmap.doors), "wall_s": 0.0,
                                      "converged_s": None, "ambiguous": None}]
    for method in ("mcl", "rbpf"):
        t0 = time.perf_counter()
        result = localize_recording(rec, lmap, config, method, init)
        wall = time.perf_counter() - t0
        at = np.searchsorted(rec.scans.stamps_ns, result.stamps_ns)
        err = position_errors(result.pose, ref[at])
        over = np.flatnonzero(err > 1.0)
        rows.append({"log": name, "method": method, "updates": len(result), "ate_m": ate_rmse(result.pose, ref[at]),
                     "max_m": float(err.max()), "first_over_1m": int(over[0]) if over.size else None,
                     "doors": len(lmap.doors), "wall_s": wall, "final_m": float(err[-1]), "ambiguous": result.ambiguous,
                     "converged_s": None if result.converged_ns is None
                     else (result.converged_ns - int(result.stamps_ns[0])) / 1e9})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--work", type=Path, default=None, help="folder for the maps (default: a temporary one)")
    ap.add_argument("--seed", type=int, default=7, help="drift seed (scripts/scanmatch_acceptance.py's default)")
    ap.add_argument("--filter-seed", type=int, default=0)
    ap.add_argument("--logs", nargs="+", default=["orebro", "intel", "aces"])
    ap.add_argument("--config", type=Path, default=None,
        help="config file (YAML, or an AMCL parameter file: Nav2, ROS 1, a ROS 1 launch file)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    ap.add_argument("--init", choices=["reference", "global"], default="reference",
                    help="the filter's start: the first corrected pose, or a uniform cloud over the map's free space")
    args = ap.parse_args()
    missing = [str(CARMEN / f"{name}-corrected.log.gz") for name in args.logs
               if not (CARMEN / f"{name}-corrected.log.gz").exists()]
    if missing:  # an empty table and exit 0 looked like a run
        raise SystemExit(f"no such CARMEN log: {', '.join(missing)} (the shared datasets are read from beside the "
                         "checkout, ../shared/datasets/carmen)")
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        rows = [row for name in args.logs
                for row in evaluate(name, work, args.seed, args.filter_seed, args.overrides, args.config,
                                    args.init)]
    print(f"drift seed {args.seed}, filter seed {args.filter_seed}, --init {args.init}")
    print("| log | method | updates | ATE (m) | max err (m) | first update > 1 m | map doors | wall (s) | "
          "converged (s) | ambiguous | final err (m) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        first = "–" if r["first_over_1m"] is None else r["first_over_1m"]
        conv = "–" if r["converged_s"] is None else f"{r['converged_s']:.1f}"
        final = f"{r['final_m']:.3f}" if "final_m" in r else "–"
        print(f"| {r['log']} | {r['method']} | {r['updates']} | {r['ate_m']:.3f} | {r['max_m']:.3f} | {first} | "
              f"{r['doors']} | {r['wall_s']:.1f} | {conv} | {r['ambiguous'] if r['ambiguous'] is not None else '–'} "
              f"| {final} |")


if __name__ == "__main__":
    main()
