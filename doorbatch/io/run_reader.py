"""Read what ``doorbatch evaluate`` takes: localization run directories, map directories, references.

A run directory (``doorbatch localize``) holds trajectory.parquet, door_states.parquet and manifest.json; the
manifest names the log (first input) and the map (``map.yaml``, ``doors.parquet``) and records ``init``,
``converged_after_s`` and ``ambiguous``. Next to a simulated log lie ``<stem>.truth.tum`` (reference) and
``<stem>.truth.yaml`` (truth): they are the run's own reference and truth when present; a log without the
TUM file gives its reference pose topic (e.g. a CARMEN log's corrected poses), if it has one. A map directory
(``doorbatch map``) holds doors.parquet; its manifest names its logs, whose folder may hold the mapping
truth ``<stem>.truth.yaml`` of the sample layout (``map.truth.yaml`` for ``map_pass*.mcap``). A TUM file is a
run too (another localizer's trajectory, e.g. AMCL's beside doorbatch's), and so is ``LOG:/TOPIC``, a pose topic
of a log (the ``/amcl_pose`` of a recorded session); their reference is ``--reference``.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import InputDataError
from doorbatch.io.manifest import Manifest
from doorbatch.io.mapdir import door_set_of, manifest_pose_source, read_door_set
from doorbatch.io.parquet import read_table
from doorbatch.io.pose_topic import POSE_TYPES, read_pose_topic
from doorbatch.io.sim_truth import SimTruth, merge_truths, output_paths, read_truth
from doorbatch.io.tum import read_tum
from doorbatch.pipeline.evaluate.report import DoorStateTable, MapTables, ReferenceTrajectory, RunTables

log = logging.getLogger(__name__)
TUM_SUFFIXES = (".tum", ".txt", ".csv")  # .csv: the TUM columns comma-separated
FloatArray = npt.NDArray[np.float64]


# What a map and a run directory hold for the next stage (hashed as inputs by evaluate and `doorbatch run`).
MAP_FILES = ("map.yaml", "map.pgm", "doors.parquet")
RUN_FILES = ("trajectory.parquet", "door_states.parquet", "trajectory.tum")


def is_run_dir(path: Path) -> bool:
    """Whether ``path`` is a localization run directory (has trajectory.parquet)."""
    return (Path(path) / "trajectory.parquet").is_file()


def is_trajectory_file(path: Path) -> bool:
    """Whether ``path`` is a trajectory file (TUM, ``.tum``/``.txt``): another localizer's output, e.g. AMCL's
    ``/amcl_pose`` exported by ``evo_traj bag2 ... --save_as_tum``."""
    p = Path(path)
    return p.is_file() and p.suffix in TUM_SUFFIXES


def is_map_dir(path: Path) -> bool:
    """Whether ``path`` is a map directory (doors.parquet and map.yaml, no trajectory)."""
    p = Path(path)
    return (p / "doors.parquet").is_file() and (p / "map.yaml").is_file() and not is_run_dir(p)


def read_reference(path: Path, config: DoorbatchConfig) -> ReferenceTrajectory:
    """A reference trajectory from a TUM file (``.tum``/``.txt``), from a pose topic of a log (``LOG:/TOPIC``,
    :func:`split_pose_topic_run`), or from a log's reference pose topic as
    :func:`~doorbatch.io.recording.load_recording` reads it (at the topic's own stamps, not resampled at the scans;
    a CARMEN log's corrected poses are at its scans), or, in a log without a laser (a motion-capture or
    ground-truth recording), the topic's poses as they are.

    Raises:
        InputDataError: unreadable, or a log without a reference pose topic.
        UsageError: ``LOG:/TOPIC`` whose topic the log lacks or that is no pose.
    """
    path = Path(path)
    if path.suffix in TUM_SUFFIXES:
        tum = read_tum(path)
        return ReferenceTrajectory(tum.stamp_ns, np.stack([tum.x, tum.y, tum.yaw], axis=1))
    topic = split_pose_topic_run(path)
    if topic is None:
        topic = _laserless_reference_topic(path, config)
    if topic is not None:
        return ReferenceTrajectory(*read_pose_topic(*topic))
    from doorbatch.io.recording import load_recording

    rec = load_recording(path, config)
    if rec.reference is None:
        raise InputDataError("--reference: the log has no reference pose topic", path=path)
    return ReferenceTrajectory(rec.reference.stamps_ns, rec.reference.poses, tuple(rec.warnings),
                               independent=not rec.reference_is_odometry)


def _laserless_reference_topic(path: Path, config: DoorbatchConfig) -> tuple[Path, str] | None:
    """(log, its reference pose topic) for a log without a laser scan, else None (a log with one is read as a
    recording).

    Raises:
        InputDataError: unreadable, or a log with neither a scan nor a reference pose topic.
    """
    from doorbatch.io.reader import open_log
    from doorbatch.records import Role

    with open_log(path, config) as reader:
        if reader.roles.topic(Role.SCAN) is not None:
            return None
        topic = reader.roles.topic(Role.REFERENCE)
        poses = sorted(t for t, info in reader.topics.items() if info.msgtype in POSE_TYPES)
        if topic is not None and reader.topics[topic].msgtype in POSE_TYPES:
            return path, topic
    found = (f"its reference is {topic}, which without a laser's clock doorbatch does not read as poses"
             if topic is not None else "no reference pose topic")
    raise InputDataError(f"--reference: a log without a laser scan and {found}; name a pose topic as LOG:/TOPIC "
                         f"(pose topics in the log: {', '.join(poses) or 'none'})", path=path)


def _sibling(log_path: Path, kind: str) -> Path:
    """The simulator's ``truth`` (YAML) or ``trajectory`` (TUM) file of a log, named as the simulator does."""
    return output_paths(log_path)[kind]


def _input_paths(manifest: Manifest) -> list[Path]:
    return [Path(str(i.get("path", ""))) for i in manifest.inputs]


def _read_door_states(path: Path) -> DoorStateTable | None:
    if not path.is_file():
        return None
    t = read_table("door_states", path).to_pydict()
    return DoorStateTable(np.asarray(t["stamp_ns"], dtype=np.int64), np.asarray(t["door_id"], dtype=np.int32),
                          np.asarray(t["angle"], dtype=np.float64), np.asarray(t["observed"], dtype=bool))


def _own_reference(log_path: Path | None, config: DoorbatchConfig) -> ReferenceTrajectory | None:
    """The simulator's ``<stem>.truth.tum`` next to the log, else the log's reference pose topic, else None."""
    if log_path is None:
        return None
    truth_tum = _sibling(log_path, "trajectory")
    if truth_tum.is_file():
        return read_reference(truth_tum, config)
    if not log_path.exists():
        return None
    try:
        return read_reference(log_path, config)
    except InputDataError as err:  # no reference topic (or unreadable now): no trajectory metrics
        log.info("%s: no reference trajectory (%s)", log_path, err)
        return None


_LogSidecars = dict[tuple[Path, bool], tuple[ReferenceTrajectory | None, SimTruth | None]]


def _log_sidecars(log_path: Path | None, config: DoorbatchConfig, find_reference: bool,
                  memo: _LogSidecars) -> tuple[ReferenceTrajectory | None, SimTruth | None]:
    """The reference (with ``find_reference``) and the truth found beside a run's log, read once per log."""
    if log_path is None:
        return None, None
    key = (log_path, find_reference)
    if key not in memo:
        truth_path = _sibling(log_path, "truth")
        memo[key] = (_own_reference(log_path, config) if find_reference else None,
                     read_truth(truth_path) if truth_path.is_file() else None)
    return memo[key]


def read_run_dirs(run_dirs: Sequence[Path], config: DoorbatchConfig, names: Sequence[str] | None = None,
                  find_reference: bool = True) -> list[RunTables]:
    """Run directories as :class:`RunTables` (see :func:`read_run_dir`); runs of the same log share one
    read of its reference and truth (an experiment has tens of runs per log).

    Raises:
        InputDataError: a missing or malformed table or manifest (names the file).
    """
    memo: _LogSidecars = {}
    labels = list(names) if names is not None else [None] * len(run_dirs)
    return [read_run_dir(d, config, n, find_reference, memo=memo) for d, n in zip(run_dirs, labels, strict=True)]


def read_run_dir(run_dir: Path, config: DoorbatchConfig, name: str | None = None,
                 find_reference: bool = True, *, memo: _LogSidecars | None = None) -> RunTables:
    """A run directory as :class:`RunTables`, with the reference and truth found next to its log (with
    ``find_reference``: ``<stem>.truth.tum``, else the log's reference pose topic). ``memo`` shares those
    reads between runs of the same log (:func:`read_run_dirs`).

    Raises:
        InputDataError: a missing or malformed table or manifest (names the file).
    """
    run_dir = Path(run_dir)
    table = read_table("trajectory", run_dir / "trajectory.parquet").to_pydict()
    if not table["stamp_ns"]:
        raise InputDataError("trajectory table is empty", path=run_dir / "trajectory.parquet")
    stamps = np.asarray(table["stamp_ns"], dtype=np.int64)
    pose = np.stack([np.asarray(table[k], dtype=np.float64) for k in ("x", "y", "yaw")], axis=1)
    manifest = Manifest.read(run_dir / "manifest.json") if (run_dir / "manifest.json").is_file() else None
    extra: dict[str, Any] = dict(manifest.extra) if manifest else {}
    inputs = _input_paths(manifest) if manifest else []
    log_path = inputs[0] if inputs else None
    maps = [p.parent for p in inputs[1:] if p.name == "doors.parquet"]  # the doors the run used (beside any YAML)
    converged_after = extra.get("converged_after_s")
    reference, truth = _log_sidecars(log_path, config, find_reference, {} if memo is None else memo)
    params = extra.get("params")
    return RunTables(
        name=name or run_dir.name, log=str(table["log"][0]), method=str(table["method"][0]), stamps_ns=stamps,
        pose=pose, init=str(extra.get("init", "reference")),
        converged_ns=None if converged_after is None else int(stamps[0]) + round(float(converged_after) * 1e9),
        ambiguous=bool(extra.get("ambiguous", False)), door_states=_read_door_states(run_dir / "door_states.parquet"),
        lost_ns=None if "lost_after_s" not in extra else tuple(  # None: a run from before the lost test
            int(stamps[0]) + round(float(t) * 1e9) for t in extra["lost_after_s"] or ()),
        map_doors=read_door_set(maps[0]) if maps and maps[0].is_dir() else None, reference=reference, truth=truth,
        params=dict(params) if isinstance(params, dict) else {}, map_path=str(inputs[1]) if len(inputs) > 1 else None,
        config=dict(manifest.config) if manifest else None)


def read_trajectory_file(path: Path, name: str | None = None) -> RunTables:
    """A TUM trajectory as a run (log: the file's name; method: its stem): a tracked start, no door states, no log
    to find a reference beside (it must be given).

    Raises:
        InputDataError: unreadable, malformed or empty.
    """
    tum = read_tum(path)
    if tum.stamp_ns.size == 0:
        raise InputDataError("trajectory file has no poses", path=path)
    return _foreign_run(name or Path(path).stem, Path(path).name, Path(path).stem, tum.stamp_ns,
                        np.stack([tum.x, tum.y, tum.yaw], axis=1))


def _foreign_run(name: str, log: str, method: str, stamps_ns: npt.NDArray[np.int64], pose: FloatArray) -> RunTables:
    """Another localizer's trajectory as a run: no convergence or ambiguity reported (NaN in the metrics, not
    "converged at its first pose"), no door states, no reference of its own."""
    return RunTables(name=name, log=log, method=method, stamps_ns=stamps_ns, pose=pose, convergence_reported=False)


def split_pose_topic_run(path: Path) -> tuple[Path, str] | None:
    """``LOG:/TOPIC`` (a log and one of its pose topics, e.g. ``session.mcap:/amcl_pose``) as (log, topic), or
    None when ``path`` is not of that form with an existing log."""
    text = str(path)
    head, sep, tail = text.rpartition(":/")
    if not sep or not head or not Path(head).exists():
        return None
    return Path(head), "/" + tail


def read_pose_topic_run(log_path: Path, topic: str, name: str | None = None) -> RunTables:
    """A pose topic of a log as a run (log: the log's name; method: the topic without its slash): a tracked
    start, no door states; its reference must be given (the log's own reference role is another topic)."""
    stamps, poses = read_pose_topic(log_path, topic)
    return _foreign_run(name or f"{log_path.name}{topic}", log_path.name, topic.strip("/"), stamps, poses)


def read_map_dir(map_dir: Path, name: str | None = None) -> MapTables:
    """A map directory's doors, with the mapping truth next to its logs when present: ``<stem>.truth.yaml`` beside
    each log (passes recorded apart, a truth each: merged, :func:`merge_truths`), else ``map.truth.yaml`` beside
    the first (the sample's layout)."""
    map_dir = Path(map_dir)
    truth: SimTruth | None = None
    pose_source: str | None = None
    manifest_path = map_dir / "manifest.json"
    if manifest_path.is_file():
        manifest = Manifest.read(manifest_path)
        pose_source = manifest_pose_source(manifest)
        logs = _input_paths(manifest)
        own = list(dict.fromkeys(c for c in (_sibling(p, "truth") for p in logs) if c.is_file()))
        shared = [p.parent / "map.truth.yaml" for p in logs[:1] if (p.parent / "map.truth.yaml").is_file()]
        if len(own) > 1:
            truth = merge_truths([read_truth(p) for p in own], own)
        elif own or shared:
            truth = read_truth((own or shared)[0])
    if not (map_dir / "doors.parquet").is_file():
        return MapTables(name or map_dir.name, read_door_set(map_dir), truth, pose_source=pose_source)
    table = read_table("doors", map_dir / "doors.parquet").to_pydict()
    return MapTables(name or map_dir.name, door_set_of(table), truth,
                     source="em" if "em" in table["source"] else "grid", pose_source=pose_source,
                     moved=np.asarray(table["moved"], dtype=np.bool_))

