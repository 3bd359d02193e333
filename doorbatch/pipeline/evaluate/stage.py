"""``doorbatch evaluate`` end to end: read run and map directories, evaluate, write the report directory.

    evaluate_run_dirs(run_dirs: Sequence[Path], out_dir: Path, config: DoorbatchConfig, *,
                      reference: Path | None = None, truth: Path | None = None) -> Evaluation

``run_dirs`` may mix localization run directories (trajectory.parquet), map directories (doors.parquet), TUM
trajectories and ``LOG:/TOPIC`` pose topics (another localizer's, e.g. AMCL's, evaluated beside doorbatch's
against ``reference``);
``reference`` is a TUM file or a log with a reference pose topic, ``truth`` a simulator truth YAML; both
override what each run finds next to its log. Writes metrics.parquet, report.md, report.html, the plots and
manifest.json into ``out_dir``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import InputDataError, UsageError
from doorbatch.io.manifest import Manifest, StageTimer
from doorbatch.io.report_writer import write_report
from doorbatch.io.run_reader import (
    MAP_FILES,
    RUN_FILES,
    is_map_dir,
    is_run_dir,
    is_trajectory_file,
    read_map_dir,
    read_pose_topic_run,
    read_reference,
    read_run_dirs,
    read_trajectory_file,
    split_pose_topic_run,
)
from doorbatch.io.sim_truth import read_truth
from doorbatch.io.staged_dir import staged_files
from doorbatch.pipeline.evaluate.report import Evaluation, MapTables, RunTables, evaluate_runs


def _names(dirs: Sequence[Path]) -> list[str]:
    """Unique labels: the folder name (a TUM file's stem), or parent/name where names repeat (runs/<log>/<method>)."""
    names = [d.stem if d.is_file() else d.name for d in dirs]
    return [f"{d.parent.name}/{n}" if names.count(n) > 1 else n for d, n in zip(dirs, names, strict=True)]


@dataclass(frozen=True)
class _Input:
    """One evaluate argument, classified once: a run directory, a map directory, a TUM trajectory, or a pose topic
    of a log (``topic``: (log, topic name))."""

    path: Path
    kind: Literal["run", "map", "tum", "topic"]
    topic: tuple[Path, str] | None = None

    @property
    def files(self) -> list[Path]:
        """What the manifest hashes: the run's tables, the map's files, the TUM file, the topic's log."""
        if self.kind in ("run", "map"):
            return [self.path / f for f in (RUN_FILES if self.kind == "run" else MAP_FILES)
                    if (self.path / f).is_file()]
        return [self.topic[0] if self.topic else self.path]


def _classify(path: Path, reference: Path | None) -> _Input:
    """What ``path`` is.

    Raises:
        InputDataError: none of the four.
        UsageError: another localizer's trajectory (TUM or pose topic) without ``reference``.
    """
    topic = split_pose_topic_run(path)
    item = (_Input(path, "run") if is_run_dir(path) else _Input(path, "map") if is_map_dir(path) else
            _Input(path, "tum") if is_trajectory_file(path) else _Input(path, "topic", topic) if topic else None)
    if item is None:
        raise InputDataError("neither a run directory (trajectory.parquet), a map directory (map.yaml, "
                             "doors.parquet), a TUM trajectory (.tum, .txt, .csv) nor LOG:/POSE_TOPIC", path=path)
    if item.kind in ("tum", "topic") and reference is None:
        raise UsageError(f"evaluate {path}: another localizer's trajectory has no reference of its own; "
                         "give --reference LOG|TUM|LOG:/TOPIC")
    return item


def evaluate_run_dirs(run_dirs: Sequence[Path], out_dir: Path, config: DoorbatchConfig, *,
                      reference: Path | None = None, truth: Path | None = None,
                      title: str = "doorbatch evaluation") -> Evaluation:
    """Evaluate run and map directories and write the report directory (see the module docstring).

    Raises:
        InputDataError: a directory that is neither a run nor a map directory, or unreadable inputs.
        UsageError: another localizer's trajectory without ``reference``.
        PipelineError: a run whose stamps match none of its reference's.
    """
    # LOG:/TOPIC stays as written (split_pose_topic_run); a path is resolved, so two spellings are one run
    unique = list(dict.fromkeys(str(d) if split_pose_topic_run(Path(d)) else str(Path(d).resolve())
                                for d in run_dirs))
    items = [_classify(Path(d), reference) for d in unique]
    reference_file = reference if reference is None else (split_pose_topic_run(reference) or (reference,))[0]
    manifest = Manifest.start(config.as_dict(), [*(f for i in items for f in i.files),
                                                 *(p for p in (reference_file, truth) if p)], command="evaluate")
    if len(unique) < len(run_dirs):  # the same run twice would count twice in every mean
        manifest.warn(f"{len(run_dirs) - len(unique)} argument(s) named a run already given: each is evaluated once")
    labelled = list(zip(items, _names([i.path for i in items]), strict=True))
    run_dirs_read = iter(read_run_dirs([i.path for i, _ in labelled if i.kind == "run"], config,
                                       [n for i, n in labelled if i.kind == "run"], find_reference=reference is None))
    runs: list[RunTables] = []
    for item, name in labelled:
        if item.kind == "run":
            runs.append(next(run_dirs_read))
        elif item.kind == "tum":
            runs.append(read_trajectory_file(item.path, name))
        elif item.topic is not None:
            runs.append(read_pose_topic_run(*item.topic, name))
    maps: list[MapTables] = [read_map_dir(i.path, n) for i, n in labelled if i.kind == "map"]
    ref = read_reference(reference, config) if reference is not None else None
    world = read_truth(truth) if truth is not None else None
    timer = StageTimer()
    with timer("metrics"):
        evaluation = evaluate_runs(runs, config, reference=ref, truth=world, maps=maps).with_title(title)
    with staged_files(out_dir) as stage:  # an interrupted write leaves ``out_dir`` as it was
        with timer("report"):
            write_report(evaluation, stage)
        for run in runs:
            if ref is None and run.reference is None:
                manifest.warn(f"run {run.name}: no reference trajectory (none beside its log, no --reference): "
                              f"convergence metrics only")
        references = [r for r in (ref, *(run.reference for run in runs)) if r is not None]
        for warning in dict.fromkeys(w for r in references for w in r.warnings):  # once each, in order
            manifest.warn(warning)
        for warning in evaluation.warnings:
            manifest.warn(warning)
        manifest.extra.update({"runs": len(runs), "maps": len(maps)})
        manifest.finish(timer)
        manifest.write(stage / "manifest.json")
    return evaluation
