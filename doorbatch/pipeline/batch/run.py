"""``doorbatch run DATASET -o OUT``: every step of a dataset, incremental, cron-safe, in parallel.

The run in outline::

    dataset  = read DATASET/dataset.yaml; config = defaults < --config < dataset config < --set
    lock     = take OUT/.doorbatch.lock (a stale one is reported and taken over)
    clean    = remove staged folders an interrupted run left
    steps    = plan the DAG: map → localize (log × method) → evaluate per site → dataset report
    run      = each step skipped when up to date, else run into a staged folder renamed into place
    summary  = OUT/summary.json, the last event of OUT/run.log, and the returned RunSummary
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator, Mapping
from contextlib import ExitStack, contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import UsageError
from doorbatch.interrupts import sigterm_as_interrupt
from doorbatch.io.atomic import atomic_write_text
from doorbatch.io.dataset import Dataset
from doorbatch.io.fingerprint_cache import read_fingerprint_cache, write_fingerprint_cache
from doorbatch.io.json_text import strict_json
from doorbatch.io.manifest import utc_now_iso
from doorbatch.io.run_lock import LockInfo, run_lock
from doorbatch.io.run_log import RUN_LOG, SUMMARY_FILE, JsonLinesHandler
from doorbatch.io.staged_dir import remove_leftovers
from doorbatch.pipeline.batch.executors import open_executor, resolve_workers
from doorbatch.pipeline.batch.ownership import check_owned_outputs
from doorbatch.pipeline.batch.plan import REPORT_DIR, Step, StepKind, plan_steps
from doorbatch.pipeline.batch.scheduler import run_steps
from doorbatch.pipeline.batch.steps import BatchJob, StepOutcome, StepStatus
from doorbatch.progress import Progress, progress_bar

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Execution:
    """Where the steps run (``--executor``, ``--workers``, ``--scheduler``): never part of the config, so
    that it changes no output."""

    executor: str = "local"  # local or dask
    workers: int = 0  # 0: one per CPU
    scheduler: str | None = None  # Dask scheduler address; None: an in-process LocalCluster

    def __post_init__(self) -> None:
        if self.executor not in ("local", "dask"):
            raise UsageError(f"--executor {self.executor!r}: expected local or dask")
        if self.scheduler is not None and self.executor != "dask":
            raise UsageError("--scheduler needs --executor dask")
        if self.workers < 0:
            raise UsageError(f"--workers {self.workers}: expected 0 (one per CPU) or more")


@dataclass(frozen=True)
class RunSummary:
    """What ``doorbatch run`` did: step counts by status, each failure with its error, where the report is."""

    dataset: str
    out: str
    steps: int
    done: int
    up_to_date: int
    failed: int
    blocked: int
    seconds: float
    report: str | None
    stale_lock: str | None
    failures: list[dict[str, str]] = field(default_factory=list)
    outcomes: list[dict[str, Any]] = field(default_factory=list)
    started_at: str = ""  # ISO 8601 UTC: a monitor tells this run's summary from an older one
    finished_at: str = ""
    status: str = "finished"  # summary.json says "running" from the start of a run until it ends

    @property
    def complete(self) -> bool:
        """Whether every step succeeded (exit 0; else exit 4)."""
        return self.failed == 0 and self.blocked == 0

    def line(self) -> str:
        """The one-line summary."""
        where = f" → {self.report}" if self.report else ""
        failed = f", {self.failed} failed, {self.blocked} blocked" if not self.complete else ""
        return (f"run of {self.dataset}: {self.steps} steps, {self.done} done, {self.up_to_date} up to date"
                f"{failed} in {self.seconds:.1f} s{where}")


@contextmanager
def run_log_handler(out: Path) -> Iterator[None]:
    """Send the ``doorbatch`` loggers' records at INFO and above to OUT/run.log for the ``with`` body."""
    root = logging.getLogger("doorbatch")
    handler = JsonLinesHandler(out / RUN_LOG)
    old_level = root.level
    root.addHandler(handler)
    if root.getEffectiveLevel() > logging.INFO:
        root.setLevel(logging.INFO)
        for other in root.handlers:  # the console keeps its level
            if other is not handler and other.level == logging.NOTSET:
                other.setLevel(old_level or logging.WARNING)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(old_level)
        handler.close()


def _log_outcome(step: Step, outcome: StepOutcome) -> None:
    extra = {"event": "step_finished", "step": step.id, "status": str(outcome.status),
             "seconds": round(outcome.seconds, 3), "error": outcome.error, "warnings": outcome.warnings}
    if outcome.ok:
        log.info("%s: %s", step.id, outcome.status, extra=extra)
    elif outcome.status is StepStatus.BLOCKED:  # the failure that blocked it is the error
        log.warning("%s: %s", step.id, outcome.error, extra=extra)
    else:
        log.error("%s: %s: %s", step.id, outcome.status, outcome.error,
                  extra={**extra, "traceback": outcome.traceback})


def _summary(dataset: Dataset, out: Path, steps: list[Step], outcomes: dict[str, StepOutcome], seconds: float,
             stale: str | None, started_at: str) -> RunSummary:
    counts = {status: sum(o.status is status for o in outcomes.values()) for status in StepStatus}
    report = out / REPORT_DIR / "report.html"
    return RunSummary(
        str(dataset.root), str(out), len(steps), counts[StepStatus.DONE], counts[StepStatus.UP_TO_DATE],
        counts[StepStatus.FAILED], counts[StepStatus.BLOCKED], seconds,
        str(report) if outcomes["report"].ok and report.exists() else None, stale,
        [{"step": s.id, "status": str(outcomes[s.id].status), "error": outcomes[s.id].error or ""}
         for s in steps if not outcomes[s.id].ok],
        [{"step": s.id, "status": str(outcomes[s.id].status), "seconds": round(outcomes[s.id].seconds, 3),
          **({"warnings": list(outcomes[s.id].warnings)} if outcomes[s.id].warnings else {})}
         for s in steps], started_at, utc_now_iso())


def _run_locked(dataset: Dataset, out: Path, config: DoorbatchConfig, execution: Execution, force: bool,
                stale: str | None, started_at: str) -> RunSummary:
    start = time.perf_counter()
    steps = plan_steps(dataset, list(config.run.methods))
    fingerprints = read_fingerprint_cache(out)
    job = BatchJob(dataset, out, config, force, fingerprints)
    with ExitStack() as stack:
        bars: dict[StepKind, Progress] = {
            kind: stack.enter_context(progress_bar(sum(s.kind is kind for s in steps), str(kind), unit="step"))
            for kind in StepKind}

        def on_outcome(step: Step, outcome: StepOutcome) -> None:
            fingerprints.update(outcome.fingerprints)
            bars[step.kind].update(1)
            _log_outcome(step, outcome)

        executor = stack.enter_context(open_executor(execution.executor, execution.workers, execution.scheduler))
        outcomes = run_steps(steps, job, executor, on_outcome,
                             lambda s: log.debug("%s: started", s.id, extra={"event": "step_started", "step": s.id}))
    write_fingerprint_cache(out, fingerprints)
    summary = _summary(dataset, out, steps, outcomes, time.perf_counter() - start, stale, started_at)
    atomic_write_text(out / SUMMARY_FILE, _json(asdict(summary)))
    return summary


def _json(data: dict[str, Any]) -> str:
    return strict_json(data) + "\n"


def _write_status(out: Path, status: str, dataset: Dataset, mine: LockInfo, **more: str) -> None:
    """summary.json while no finished run's summary stands: the status, the run (pid, host, start) and ``more``."""
    atomic_write_text(out / SUMMARY_FILE, _json({"status": status, "dataset": str(dataset.root), "out": str(out),
                                                 "pid": mine.pid, "host": mine.host, "started_at": mine.started_at,
                                                 **more}))


def run_dataset(dataset: Dataset, out: Path, config: DoorbatchConfig, execution: Execution | None = None, *,
                force: bool = False) -> RunSummary:
    """Run every step of ``dataset`` into ``out`` (see the module docstring); returns the summary, which
    lists failed steps (the caller turns them into exit code 4).

    Raises:
        ConfigError: a site named like one of OUT's own entries (``plan.OUT_ENTRIES``).
        UsageError: OUT holds a folder the run would replace that it did not write, or the dataset's inputs
            (:func:`~doorbatch.pipeline.batch.ownership.check_owned_outputs`).
        OutputLockedError: another live run holds ``out``.
        OptionalDependencyError: the Dask executor without the ``dask`` extra.
        KeyboardInterrupt: Ctrl-C or SIGTERM; staged folders are removed and completed steps stay.
    """
    out = Path(out).resolve()
    execution = execution or Execution()
    # a dataset that cannot be planned, or an OUT holding folders the run would replace that are not its own,
    # touches nothing in OUT
    check_owned_outputs(out, plan_steps(dataset, list(config.run.methods)), dataset)
    with run_lock(out) as (mine, stale), run_log_handler(out), sigterm_as_interrupt():
        log.info("run of %s started", dataset.root, extra={
            "event": "run_started", "dataset": str(dataset.root), "pid": mine.pid, "host": mine.host,
            "config_hash": config.hash(), "force": force, "executor": execution.executor,
            "workers": resolve_workers(execution.workers), "scheduler": execution.scheduler})
        stale_text = None if stale is None else stale.describe()
        if stale is not None:
            log.warning("took over the stale lock of %s", stale_text,
                        extra={"event": "stale_lock", "holder": stale_text})
        # until this run ends, summary.json says it runs: a run killed midway leaves that, not the last one's summary
        _write_status(out, "running", dataset, mine)
        for path in remove_leftovers(out):
            log.warning("removed %s left by an interrupted run", path, extra={"event": "leftover_removed",
                                                                            "path": str(path)})
        try:
            summary = _run_locked(dataset, out, config, execution, force, stale_text, mine.started_at)
        except BaseException as err:
            _write_status(out, "interrupted" if isinstance(err, KeyboardInterrupt) else "failed", dataset, mine,
                          finished_at=utc_now_iso())
            if not isinstance(err, KeyboardInterrupt):
                raise
            removed = remove_leftovers(out)
            log.error("run interrupted; removed %d staged folder(s)", len(removed), extra={"event": "run_interrupted"})
            raise
        log.info(summary.line(), extra={"event": "run_finished", **asdict(summary)})
    return summary


def prepare_run(dataset_path: Path, config_file: Path | None, overrides: tuple[str, ...] = (),
                launch_args: Mapping[str, str] | None = None) -> tuple[Dataset, DoorbatchConfig]:
    """Read the dataset and resolve the config: defaults < ``config_file`` (a launch file read with
    ``launch_args``) < the dataset's ``config:`` < ``overrides``.

    Raises:
        ConfigError: a bad dataset.yaml or config.
    """
    from doorbatch.config import load_config
    from doorbatch.io.dataset import read_dataset

    dataset = read_dataset(Path(dataset_path).resolve())  # manifests name absolute inputs: any worker finds them
    return dataset, load_config(config_file, overrides, extra=dataset.config,
                                extra_source=f"{dataset.root / 'dataset.yaml'} (config:)", launch_args=launch_args)
