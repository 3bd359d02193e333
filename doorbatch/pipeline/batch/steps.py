"""Executing one step of ``doorbatch run``: skip it when up to date, else run its stage into a staged folder.

:func:`execute_step` is what the executors call, in this process, a pool worker or a Dask worker: it takes
only picklable values and never raises for a step that fails (the error goes into the outcome), so that one
failing log does not stop the others. An interruption (Ctrl-C, SIGTERM turned into ``KeyboardInterrupt``)
propagates, and the step's staged folder is removed on the way out.
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import DoorbatchError
from doorbatch.io.dataset import Dataset, Site
from doorbatch.io.fingerprint_cache import FingerprintCache
from doorbatch.io.manifest import StageTimer, utc_now_iso
from doorbatch.io.run_reader import MAP_FILES, RUN_FILES
from doorbatch.io.sim_truth import output_paths
from doorbatch.io.staged_dir import staged_dir
from doorbatch.pipeline.batch.freshness import StepKey, is_up_to_date, recorded_key, stamp_manifest, step_key
from doorbatch.pipeline.batch.plan import METRICS_DIR, TRAJECTORIES_DIR, Step, StepKind, map_dir


class StepStatus(StrEnum):
    """How a step ended."""

    DONE = "done"  # ran and wrote its folder
    UP_TO_DATE = "up_to_date"  # skipped: inputs and config unchanged
    FAILED = "failed"  # raised; its previous folder (if any) is left as it was
    BLOCKED = "blocked"  # not run: a step it needs failed


@dataclass(frozen=True)
class StepOutcome:
    """The result of one step, as the run summary and run.log report it."""

    step_id: str
    status: StepStatus
    seconds: float = 0.0
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    traceback: str | None = None  # of an internal error, for run.log
    fingerprints: dict[str, dict[str, Any]] = field(default_factory=dict)  # new cache entries

    @property
    def ok(self) -> bool:
        """Whether the step's folder is complete and current."""
        return self.status in (StepStatus.DONE, StepStatus.UP_TO_DATE)


@dataclass(frozen=True)
class BatchJob:
    """What every step needs to know (picklable: it travels to pool and Dask workers)."""

    dataset: Dataset
    out: Path
    config: DoorbatchConfig
    force: bool = False
    fingerprints: dict[str, dict[str, Any]] = field(default_factory=dict)  # the cache when the run started

    def site(self, name: str | None) -> Site:
        """The dataset's site of this name."""
        return next(s for s in self.dataset.sites if s.name == name)


def _existing(paths: Sequence[Path]) -> list[Path]:
    return [p for p in paths if p.exists()]


def _inputs(step: Step, job: BatchJob, usable: Sequence[Step]) -> tuple[list[Path], dict[str, object]]:
    """The files a step reads (in a fixed order) and its parameters."""
    out, run = job.out, job.config.run
    if step.kind is StepKind.MAP:
        return list(job.site(step.site).mapping), {"stages": run.map_stages}
    if step.kind is StepKind.LOCALIZE:
        assert step.log is not None
        site_map = out / map_dir(str(step.site))
        return [step.log, *_existing([site_map / f for f in MAP_FILES])], {"method": step.method, "init": run.init}
    if step.kind is StepKind.EVALUATE:
        site = job.site(step.site)
        files = _existing([out / map_dir(site.name) / f for f in MAP_FILES])
        # the truth each reader finds: the site's, else beside the mapping logs; beside each localization log
        files += [site.truth] if site.truth is not None else _existing(
            [*(output_paths(p)["truth"] for p in site.mapping), site.mapping[0].parent / "map.truth.yaml"])
        for u in usable:  # each run's reference: the truth TUM beside its log, else the log's reference topic
            assert u.log is not None
            files += _existing([out / u.out_dir / f for f in RUN_FILES])
            files += _existing([output_paths(u.log)["trajectory"], output_paths(u.log)["truth"], u.log])
        return files, {"runs": [u.out_dir for u in usable], "left_out": left_out(step, usable)}
    # the dataset report re-reads what each site evaluation read: their step keys stand for those inputs
    return [out / u.out_dir / "metrics.parquet" for u in usable], {
        "sites": [u.site for u in usable], "site_keys": [recorded_key(out / u.out_dir) for u in usable],
        "left_out": left_out(step, usable)}


def left_out(step: Step, usable: Sequence[Step]) -> list[str]:
    """The steps ``step`` would use that failed or were blocked (its report names them; part of its key, so
    that the report is made again when they change)."""
    ok = {u.id for u in usable}
    return sorted(d for d in step.uses if d not in ok)


def _run_stage(step: Step, job: BatchJob, usable: Sequence[Step], dest: Path) -> list[str]:
    """Run the step's stage, writing into ``dest``; return its warnings."""
    from doorbatch.pipeline.batch import stages

    if step.kind is StepKind.MAP:
        return stages.build_site_map(job.site(step.site), dest, job.config)
    if step.kind is StepKind.LOCALIZE:
        assert step.log is not None and step.method is not None
        return stages.localize_log(step.log, job.out / map_dir(str(step.site)), dest, job.config, step.method)
    missing = left_out(step, usable)
    if step.kind is StepKind.EVALUATE:
        return stages.evaluate_site(job.site(step.site), job.out, [u.out_dir for u in usable], dest, job.config,
                                    missing)
    return stages.dataset_report(job.dataset, job.out, usable, dest, job.config, missing)


def _execute(step: Step, job: BatchJob, usable: Sequence[Step], key: StepKey) -> list[str]:
    started_at = utc_now_iso()
    with staged_dir(job.out / step.out_dir) as dest:
        timer = StageTimer()  # for a stage that writes no manifest of its own
        with timer(step.kind.value):
            warnings = _run_stage(step, job, usable, dest)
        stamp_manifest(dest, key, job.config.as_dict(), started_at, warnings, timer)
    return warnings


def wrapped_interrupt(err: BaseException) -> KeyboardInterrupt | None:
    """The ``KeyboardInterrupt`` in ``err``'s cause/context chain, if any: Python wraps an exception raised in
    some places into another (a SIGTERM arriving while an import runs a dataclass's ``__set_name__`` surfaces as
    ``RuntimeError``), and an interruption must still unwind as one, not fail the step."""
    seen: set[int] = set()
    current: BaseException | None = err
    while current is not None and id(current) not in seen:
        if isinstance(current, KeyboardInterrupt):
            return current
        seen.add(id(current))
        current = current.__cause__ or current.__context__
    return None


def execute_step(step: Step, job: BatchJob, usable: Sequence[Step] = ()) -> StepOutcome:
    """Run ``step`` unless its folder is up to date (or ``job.force``); never raises for a failing step.

    Args:
        step: The step.
        job: Dataset, output root, config.
        usable: The steps of ``step.uses`` that succeeded (their outputs are read).
    """
    start = time.perf_counter()
    cache = FingerprintCache(job.fingerprints)
    try:
        key = step_key(step.kind, job.config.as_dict(), *_inputs(step, job, usable), fingerprint=cache.fingerprint)
        # the dataset report's tables lie beside its folder (OUT/metrics, OUT/trajectories)
        beside = (METRICS_DIR, TRAJECTORIES_DIR) if step.kind is StepKind.REPORT else ()
        if not job.force and is_up_to_date(job.out / step.out_dir, key.digest) and all(
                (job.out / d).is_dir() for d in beside):
            return StepOutcome(step.id, StepStatus.UP_TO_DATE, time.perf_counter() - start, fingerprints=cache.new)
        warnings = _execute(step, job, usable, key)
    except DoorbatchError as err:
        return StepOutcome(step.id, StepStatus.FAILED, time.perf_counter() - start, str(err),
                           fingerprints=cache.new)
    except OSError as err:  # the machine, not the data or the code: a full disk, a file where a folder must go
        if (interrupt := wrapped_interrupt(err)) is not None:
            raise interrupt from err
        where = f" ({err.filename})" if err.filename else ""
        return StepOutcome(step.id, StepStatus.FAILED, time.perf_counter() - start,
                           f"file system: {err.strerror or err}{where}", traceback=traceback.format_exc(),
                           fingerprints=cache.new)
    except Exception as err:  # a bug or an unforeseen data problem: this step fails, the batch goes on
        interrupt = wrapped_interrupt(err)
        if interrupt is not None:
            raise interrupt from err
        return StepOutcome(step.id, StepStatus.FAILED, time.perf_counter() - start,
                           f"internal error ({type(err).__name__}: {err})", traceback=traceback.format_exc(),
                           fingerprints=cache.new)
    return StepOutcome(step.id, StepStatus.DONE, time.perf_counter() - start, warnings=warnings,
                       fingerprints=cache.new)
