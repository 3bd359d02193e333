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
from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import InputDataError, UsageError
from doorbatch.io.manifest import Manifest
from doorbatch.io.report_writer import write_report
from doorbatch.io.run_reader import (
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
from doorbatch.pipeline.evaluate.report import Evaluation, MapTables, RunTables, evaluate_runs


def _names(dirs: Sequence[Path]) -> list[str]:
    """Unique labels: the folder name (a TUM file's stem), or parent/name where names repeat (runs/<log>/<method>)."""
    names = [d.stem if d.is_file() else d.name for d in dirs]
    return [f"{d.parent.name}/{n}" if names.count(n) > 1 else n for d, n in zip(dirs, names, strict=True)]


def _input_file(path: Path, topic: tuple[Path, str] | None) -> Path:
    """The file of an input that the manifest hashes: a run's trajectory, a TUM file, a pose topic's log, a map's
    doors."""
    if is_run_dir(path):
        return path / "trajectory.parquet"
    if is_trajectory_file(path):
        return path
    return topic[0] if topic is not None else path / "doors.parquet"


def evaluate_run_dirs(run_dirs: Sequence[Path], out_dir: Path, config: DoorbatchConfig, *,
                      reference: Path | None = None, truth: Path | None = None,
                      title: str = "doorbatch evaluation") -> Evaluation:
    """Evaluate run and map directories and write the report directory (see the module docstring).

    Raises:
        InputDataError: a directory that is neither a run nor a map directory, or unreadable inputs.
        PipelineError: a run whose stamps match none of its reference's.
    """
    dirs = [Path(d) for d in run_dirs]
    topics = {d: split_pose_topic_run(d) for d in dirs}
    for d in dirs:
        if not (is_run_dir(d) or is_map_dir(d) or is_trajectory_file(d) or topics[d]):
            raise InputDataError("neither a run directory (trajectory.parquet), a map directory (map.yaml, "
                                 "doors.parquet), a TUM trajectory (.tum, .txt) nor LOG:/POSE_TOPIC", path=d)
        if (is_trajectory_file(d) or topics[d]) and reference is None:
            raise UsageError(f"evaluate {d}: another localizer's trajectory has no reference of its own; "
                             "give --reference LOG|TUM")
    inputs = [_input_file(d, topics[d]) for d in dirs]
    manifest = Manifest.start(config.as_dict(), [*inputs, *(p for p in (reference, truth) if p is not None)],
                              command="evaluate")
    labelled = list(zip(dirs, _names(dirs), strict=True))
    run_dirs_read = iter(read_run_dirs([d for d, _ in labelled if is_run_dir(d)], config,
                                       [n for d, n in labelled if is_run_dir(d)], find_reference=reference is None))
    runs: list[RunTables] = []
    for d, n in labelled:
        topic = topics[d]
        if is_run_dir(d):
            runs.append(next(run_dirs_read))
        elif is_trajectory_file(d):
            runs.append(read_trajectory_file(d, n))
        elif topic is not None:
            runs.append(read_pose_topic_run(*topic, n))
    maps: list[MapTables] = [read_map_dir(d, n) for d, n in labelled if is_map_dir(d)]
    ref = read_reference(reference, config) if reference is not None else None
    world = read_truth(truth) if truth is not None else None
    evaluation = evaluate_runs(runs, config, reference=ref, truth=world, maps=maps).with_title(title)
    write_report(evaluation, out_dir)
    manifest.extra.update({"runs": len(runs), "maps": len(maps)})
    manifest.finish()
    manifest.write(out_dir / "manifest.json")
    return evaluation
