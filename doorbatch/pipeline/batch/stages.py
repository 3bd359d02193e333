"""The stage behind each kind of step, called with a staged output folder to fill.

Each returns the stage's warnings. The map and localize stages are ``doorbatch map`` and ``doorbatch
localize`` themselves (:func:`~doorbatch.pipeline.map_run.run_map`,
:func:`~doorbatch.pipeline.localize.run.run_localize`); evaluation is ``doorbatch evaluate``'s library API.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from doorbatch.config import DoorbatchConfig
from doorbatch.io.dataset import Dataset, Site
from doorbatch.io.dataset_tables import concat_tables, write_site_partition
from doorbatch.io.parquet import read_table
from doorbatch.io.staged_dir import staged_dir
from doorbatch.pipeline.batch.freshness import recorded_step
from doorbatch.pipeline.batch.plan import METRICS_DIR, TRAJECTORIES_DIR, Step, map_dir

if TYPE_CHECKING:
    from doorbatch.pipeline.evaluate.report import Evaluation, MapTables, RunTables

# The report's plots go through matplotlib.pyplot, whose figure registry is global: steps running as threads
# (the Dask LocalCluster) write their reports one at a time.
_PYPLOT_LOCK = threading.Lock()


def _write_report(evaluation: Evaluation, dest: Path) -> None:
    from doorbatch.io.report_writer import write_report

    with _PYPLOT_LOCK:
        write_report(evaluation, dest)


def build_site_map(site: Site, dest: Path, config: DoorbatchConfig) -> list[str]:
    """The site's map from its mapping logs (one pass each) into ``dest``."""
    from doorbatch.pipeline.map_run import run_map

    _, summary = run_map(list(site.mapping), dest, config, config.run.map_stages)
    return list(summary.warnings)


def localize_log(log: Path, map_dir: Path, dest: Path, config: DoorbatchConfig, method: str) -> list[str]:
    """Localize one log on the site's map with one method into ``dest``."""
    from doorbatch.pipeline.localize.run import run_localize

    result, _ = run_localize(log, map_dir, dest, config, method, config.run.init)
    return list(result.warnings)


def _run_name(run_dir: str) -> str:
    """``<log>/<method>`` of an OUT-relative run folder ``<site>/runs/<log>/<method>``."""
    return "/".join(run_dir.split("/")[-2:])


def _site_tables(site: Site, out: Path, run_dirs: Sequence[str], config: DoorbatchConfig,
                 prefix: str = "") -> tuple[list[RunTables], list[MapTables]]:
    """The site's runs (each with the reference and truth found beside its log) and its door map, scored
    against the dataset's truth of the site when it names one (else the truth found beside its logs)."""
    from doorbatch.io.run_reader import read_map_dir, read_run_dirs
    from doorbatch.io.sim_truth import read_truth

    tables = read_run_dirs([out / r for r in run_dirs], config, [f"{prefix}{_run_name(r)}" for r in run_dirs])
    if prefix:  # the dataset report: logs of two sites may share a file name, never a row
        tables = [replace(t, log=f"{prefix}{t.log}") for t in tables]
    door_map = read_map_dir(out / map_dir(site.name), f"{site.name}/map")
    if site.truth is not None:
        door_map = replace(door_map, truth=read_truth(site.truth))
    return tables, [door_map]


def evaluate_site(site: Site, out: Path, run_dirs: Sequence[str], dest: Path, config: DoorbatchConfig,
                  left_out: Sequence[str] = ()) -> list[str]:
    """Metrics, plots and report of the site's map and of each run that succeeded, into ``dest``; the report
    names the runs ``left_out`` (failed or blocked), and so do the returned warnings, with the evaluation's own
    (metrics it cannot give, e.g. against a reference that is the odometry again)."""
    from doorbatch.pipeline.evaluate.report import evaluate_runs

    tables, maps = _site_tables(site, out, run_dirs, config)
    evaluation = evaluate_runs(tables, config, maps=maps).with_title(f"doorbatch run: site {site.name}", left_out)
    _write_report(evaluation, dest)
    return [*(f"left out: {step} (failed or blocked)" for step in left_out), *evaluation.warnings]


def dataset_report(dataset: Dataset, out: Path, evaluations: Sequence[Step], dest: Path,
                   config: DoorbatchConfig, left_out: Sequence[str] = ()) -> list[str]:
    """The dataset report over every site that was evaluated, into ``dest`` (OUT/report), and the site
    partitions of the dataset-level tables OUT/metrics/site=<site>/ and OUT/trajectories/site=<site>/. The
    report names the steps it lacks: the evaluations ``left_out`` and the runs each site's evaluation left out (its
    step record's ``left_out``)."""
    from doorbatch.pipeline.evaluate.report import evaluate_runs

    by_name = {s.name: s for s in dataset.sites}
    tables: list[RunTables] = []
    maps: list[MapTables] = []
    missing = list(left_out)
    with staged_dir(out / METRICS_DIR) as metrics, staged_dir(out / TRAJECTORIES_DIR) as trajectories:
        for ev in evaluations:
            site = by_name[str(ev.site)]
            params = (recorded_step(out / ev.out_dir) or {}).get("params", {})
            run_dirs = [str(r) for r in params.get("runs", [])]
            missing += [str(r) for r in params.get("left_out", [])]
            write_site_partition("metrics", read_table("metrics", out / ev.out_dir / "metrics.parquet"), metrics,
                                 site.name)
            write_site_partition("trajectory", concat_tables("trajectory", [
                out / r / "trajectory.parquet" for r in run_dirs]), trajectories, site.name)
            site_runs, site_maps = _site_tables(site, out, run_dirs, config, prefix=f"{site.name}/")
            tables += site_runs
            maps += site_maps
        evaluation = evaluate_runs(tables, config, maps=maps).with_title(f"doorbatch run: {dataset.root.name}",
                                                                          missing)
        _write_report(evaluation, dest)
    return []
