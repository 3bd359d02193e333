"""Paper 003's Tables I and II on simulated door scenes, with the paper's z-tests, beside the paper's numbers.

Usage::

    python scripts/doorpose_tables.py configs/experiments/doorpose_table1.yaml [--metrics OUT.parquet] [--json]
    python scripts/doorpose_tables.py configs/experiments/doorpose_table2.yaml

Prints a Markdown table (mean ± std of the summed |Δx| + |Δy| + |Δθ| error per method, the paper's figures,
and the one-sided z-tests at 5 %); ``--metrics`` writes the rows of DESIGN's metrics.parquet.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import yaml

from doorbatch.config import load_config
from doorbatch.io.parquet import write_table
from doorbatch.pipeline.doorpose.experiment import (
    DoorPoseExperiment,
    compare_fits,
    compare_goal_updating,
    fit_comparison_metrics,
    goal_updating_metrics,
    z_test_greater,
)
from doorbatch.pipeline.evaluate.report import metric_columns

PAPER_TABLE_1 = {"naive": (0.3212, 0.1774), "lsq": (0.1167, 0.0667), "ransac": (0.0311, 0.0062)}
PAPER_TABLE_2 = {"initial": (0.2492, 0.0948), "continuous": (0.0650, 0.0361)}
LABEL = {"naive": "Naive", "lsq": "Least Squares", "ransac": "RANSAC", "initial": "Initial",
         "continuous": "Continuous"}


def _table(errors: dict[str, np.ndarray], paper: dict[str, tuple[float, float]]) -> list[str]:
    lines = ["| method | n | mean | std | paper mean | paper std |", "| --- | --- | --- | --- | --- | --- |"]
    for name, err in errors.items():
        ok = err[np.isfinite(err)]
        fails = f" ({err.size - ok.size} no estimate)" if ok.size < err.size else ""
        lines.append(f"| {LABEL[name]} | {ok.size}{fails} | {ok.mean():.4f} | {ok.std(ddof=1):.4f} | "
                     f"{paper[name][0]:.4f} | {paper[name][1]:.4f} |")
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("experiment", type=Path)
    ap.add_argument("--metrics", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    exp = DoorPoseExperiment.model_validate(yaml.safe_load(args.experiment.read_text()))
    config = load_config(extra=exp.config)
    t0 = time.perf_counter()
    params = {"experiment": exp.experiment, "samples": exp.samples, "seed": exp.seed}
    if exp.experiment == "doorpose_fit_comparison":
        fits = compare_fits(exp, config)
        lines = _table(fits.errors, PAPER_TABLE_1)
        r = fits.errors["ransac"]
        for other in ("lsq", "naive"):
            both = np.isfinite(fits.errors[other]) & np.isfinite(r)
            z, p = z_test_greater(r[both], fits.errors[other][both])
            lines.append(f"\nz-test H1 {LABEL[other]} error > RANSAC error: z = {z:.2f}, p = {p:.2g} "
                         f"({'reject H0' if p < 0.05 else 'keep H0'} at 5 %)")
        lines.append(f"\nhandle side correct on {fits.handle_correct} / {fits.handle_checked} samples with the "
                     f"handle visible; {fits.draws} scenes drawn for {exp.samples} with a usable door box")
        rows = fit_comparison_metrics(fits, args.experiment.stem, params)
        summary = {k: float(np.mean(v[np.isfinite(v)])) for k, v in fits.errors.items()}
    else:
        upd = compare_goal_updating(exp, config)
        lines = _table(upd.errors, PAPER_TABLE_2)
        z, p = z_test_greater(upd.errors["continuous"], upd.errors["initial"])
        lines.append(f"\nz-test H1 Initial error > Continuous error: z = {z:.2f}, p = {p:.2g} "
                     f"({'reject H0' if p < 0.05 else 'keep H0'} at 5 %)")
        lines.append(f"\nreached the goal tolerance: initial {int(upd.reached['initial'].sum())}/{exp.samples}, "
                     f"continuous {int(upd.reached['continuous'].sum())}/{exp.samples}; "
                     f"{upd.draws} start poses drawn")
        rows = goal_updating_metrics(upd, args.experiment.stem, params)
        summary = {k: float(v.mean()) for k, v in upd.errors.items()}
    lines.append(f"\n{time.perf_counter() - t0:.1f} s")
    if args.metrics is not None:
        write_table("metrics", metric_columns(rows), args.metrics)
    print(json.dumps(summary) if args.json else "\n".join(lines))


if __name__ == "__main__":
    main()
