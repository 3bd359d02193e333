"""The steps of ``doorbatch run`` over a dataset and their dependencies (a DAG, listed in topological order).

Each step owns one output folder under OUT (written whole or not at all) and names the steps whose outputs
it reads: those it ``needs`` (it is blocked when one failed) and those it ``uses`` (it runs on the ones that
succeeded), so one failing log leaves every other output complete.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

from doorbatch.errors import ConfigError
from doorbatch.io.dataset import DATASET_FILE, Dataset, Site, log_name
from doorbatch.io.run_lock import LOCK_NAME
from doorbatch.io.run_log import RUN_LOG, SUMMARY_FILE

REPORT_DIR = "report"
METRICS_DIR = "metrics"
TRAJECTORIES_DIR = "trajectories"
# What OUT holds besides one folder per site: no site may take these names.
OUT_ENTRIES = frozenset({REPORT_DIR, METRICS_DIR, TRAJECTORIES_DIR, SUMMARY_FILE, RUN_LOG, LOCK_NAME})


class StepKind(StrEnum):
    """What a step does."""

    MAP = "map"
    LOCALIZE = "localize"
    EVALUATE = "evaluate"
    REPORT = "report"


@dataclass(frozen=True)
class Step:
    """One node of the DAG. ``out_dir`` is relative to OUT; ``log`` and ``method`` only for localize."""

    id: str
    kind: StepKind
    out_dir: str
    needs: tuple[str, ...] = ()
    uses: tuple[str, ...] = ()
    site: str | None = None
    log: Path | None = None
    method: str | None = None

    @property
    def deps(self) -> tuple[str, ...]:
        """Every step this one waits for."""
        return self.needs + self.uses


def map_dir(site: str) -> str:
    """OUT-relative map folder of a site."""
    return f"{site}/map"


def run_dir(site: str, log: Path, method: str) -> str:
    """OUT-relative run folder of one log and method."""
    return f"{site}/runs/{log_name(log)}/{method}"


def site_report_dir(site: str) -> str:
    """OUT-relative evaluation folder of a site."""
    return f"{site}/{REPORT_DIR}"


def _site_steps(site: Site, methods: list[str]) -> list[Step]:
    map_id = f"map:{site.name}"
    steps = [Step(map_id, StepKind.MAP, map_dir(site.name), site=site.name)]
    for log in site.localization:
        for method in methods:
            steps.append(Step(f"localize:{site.name}/{log_name(log)}/{method}", StepKind.LOCALIZE,
                              run_dir(site.name, log, method), (map_id,), site=site.name, log=log, method=method))
    runs = tuple(s.id for s in steps[1:])
    # evaluation needs the map (door-map scoring) and uses the runs that succeeded
    steps.append(Step(f"evaluate:{site.name}", StepKind.EVALUATE, site_report_dir(site.name), (map_id,), runs,
                      site=site.name))
    return steps


def plan_steps(dataset: Dataset, methods: list[str]) -> list[Step]:
    """Every step of a dataset, dependencies first: per site map → localize (log × method) → evaluate, then
    the dataset report over every site's evaluation."""
    steps: list[Step] = []
    for site in dataset.sites:
        if site.name in OUT_ENTRIES:
            raise ConfigError(f"{dataset.root / DATASET_FILE}: site name {site.name!r} is taken by OUT/{site.name} of "
                              "the batch itself; rename the site")
        steps += _site_steps(site, methods)
    evaluations = tuple(s.id for s in steps if s.kind is StepKind.EVALUATE)
    steps.append(Step("report", StepKind.REPORT, REPORT_DIR, (), evaluations))
    return steps
