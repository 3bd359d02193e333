"""Global localization success rates of MCL and the RBPF: particles uniform over the map's free space.

A thin front end to the experiment library (``doorbatch evaluate --experiment configs/experiments/global.yaml``
runs the full paper 000 Figs. 8-9 sweep). Success (doorbatch.pipeline.evaluate.localization_success): the filter
converges (weighted std ≤ localize.converged_xy_std_m and converged_yaw_std_deg) within
evaluate.global_success_window_s of the first scan, and the estimate is within evaluate.global_success_xy_m and
global_success_yaw_deg of the reference at convergence and at the end of the log. Particles:
``localize.global_particles`` = ``localize.max_particles`` = N. Writes the report (with the success plot) into
``--out`` and prints its table.

Usage::

    python scripts/localize_global.py --map /tmp/lm/map [--logs datasets/sample/logs] [--cases closed partial] \
        [--particles 1000 2000 5000 10000 20000 50000] [--seeds 0 1 ... 9] [--out /tmp/lm/global] [--workers 2]
"""

from __future__ import annotations

import argparse
from pathlib import Path

from doorbatch.config import load_config
from doorbatch.io.report_writer import stdout_table
from doorbatch.pipeline.evaluate.experiment import ExperimentSpec, run_experiment


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=Path, default=None)
    ap.add_argument("--truth-map", action="store_true",
                    help="instead of --map, each log\'s simulator truth: static map and all doors (<log>.truth.yaml)")
    ap.add_argument("--logs", type=Path, default=Path("datasets/sample/logs"))
    ap.add_argument("--cases", nargs="+", default=["closed", "partial"])
    ap.add_argument("--methods", nargs="+", default=["mcl", "rbpf"])
    ap.add_argument("--particles", nargs="+", type=int, default=[1000, 2000, 5000, 10000, 20000, 50000])
    ap.add_argument("--seeds", nargs="+", type=int, default=list(range(10)))
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    ap.add_argument("--out", type=Path, default=Path("/tmp/doorbatch-global"), help="report directory")
    ap.add_argument("--workers", type=int, default=1)
    args = ap.parse_args()
    if (args.map is None) == (not args.truth_map):
        ap.error("give exactly one of --map and --truth-map")
    map_source = "truth" if args.truth_map else args.map.resolve()
    spec = ExperimentSpec(name="global", map=map_source, init="global", methods=tuple(args.methods),
                          logs=tuple((args.logs / f"loc_{c}.mcap").resolve() for c in args.cases),
                          particles=tuple(args.particles), seeds=tuple(args.seeds), set=tuple(args.overrides))
    print(stdout_table(run_experiment(spec, args.out, load_config(), workers=args.workers)))


if __name__ == "__main__":
    main()
