"""Tracking accuracy of MCL and the RBPF on simulated logs with closed, open and partially open doors.

A thin front end to the experiment library (``doorbatch evaluate --experiment configs/experiments/tracking.yaml``
runs the full paper 000 Figs. 5-7 sweep): for each log ``loc_{case}.mcap`` in ``--logs`` and each seed, localize
with ``--init reference`` on the map directory ``--map`` and evaluate against the log's ground truth (APE/RPE as
evo, door-state error against ``<log>.truth.yaml``). Writes the report into ``--out`` and prints its table.

Usage::

    doorbatch map datasets/sample/logs/map_pass*.mcap -o /tmp/lm/map
    python scripts/localize_tracking.py --map /tmp/lm/map --logs datasets/sample/logs [--seeds 0 1] \
        [--methods mcl rbpf] [--config FILE] [--set localize.sigma_hit=0.1 ...] [--out /tmp/lm/tracking] \
        [--workers 2]

``--config`` is the base config of every run, as ``doorbatch --config`` takes it (a Nav2 parameter file too).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from doorbatch.config import load_config
from doorbatch.io.report_writer import stdout_table
from doorbatch.pipeline.evaluate.experiment import ExperimentSpec, run_experiment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=Path, default=None, help="map directory (doorbatch map)")
    ap.add_argument("--truth-map", action="store_true",
                    help="instead of --map, each log\'s simulator truth: static map and all doors (<log>.truth.yaml)")
    ap.add_argument("--logs", type=Path, default=Path("datasets/sample/logs"))
    ap.add_argument("--cases", nargs="+", default=["closed", "open", "partial"])
    ap.add_argument("--methods", nargs="+", default=["mcl", "rbpf"])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    ap.add_argument("--config", type=Path, default=None,
                    help="config file (YAML, or an AMCL parameter file: Nav2, ROS 1, a ROS 1 launch file)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    ap.add_argument("--out", type=Path, default=Path("/tmp/doorbatch-tracking"), help="report directory")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    if (args.map is None) == (not args.truth_map):
        ap.error("give exactly one of --map and --truth-map")
    map_source = "truth" if args.truth_map else args.map.resolve()
    spec = ExperimentSpec(name="tracking", map=map_source, init="reference", methods=tuple(args.methods),
                          logs=tuple((args.logs / f"loc_{c}.mcap").resolve() for c in args.cases),
                          seeds=tuple(args.seeds), set=tuple(args.overrides))
    print(stdout_table(run_experiment(spec, args.out, load_config(args.config), workers=args.workers)))


if __name__ == "__main__":
    main()
