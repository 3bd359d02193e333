"""``doorbatch evaluate``'s numerics: localization runs and door maps → metric rows and plot data. Pure.

Public API (the ``run`` stage and notebooks call these; :mod:`doorbatch.io.report_writer` writes the result)::

    run_tables_from_result(result: LocalizationResult, *, name=None, init="reference", map_doors=None,
                           reference=None, truth=None, params=None) -> RunTables   # a run in memory

    evaluate_runs(runs: Sequence[RunTables], config: DoorbatchConfig, *,
                  reference: ReferenceTrajectory | None = None, truth: SimTruth | None = None,
                  maps: Sequence[MapTables] = ()) -> Evaluation
    evaluate_run_dirs(run_dirs: Sequence[Path], out_dir: Path, config: DoorbatchConfig, *,
                      reference: Path | None = None, truth: Path | None = None) -> Evaluation
        (in :mod:`doorbatch.pipeline.evaluate.stage`: reads the run and map directories, evaluates, writes
        metrics.parquet, report.md, report.html and the PNG plots into ``out_dir``)

``reference`` and ``truth`` given here override each run's own (``RunTables.reference``/``.truth``, which the
reader finds next to the run's log: ``<log stem>.truth.tum`` and ``<log stem>.truth.yaml``).

Per localization run (metric names; rotations in ``evaluate.angle_unit``):
``ape_trans_<stat>`` and ``ape_rot_<stat>``, ``rpe_trans_<stat>`` and ``rpe_rot_<stat>`` (stat: rmse, mean,
median, std, min, max, as evo, see :mod:`trajectory_metrics`), ``associated_poses``, ``rpe_pairs``;
``converged`` (0/1), ``time_to_converge_s``, ``ambiguous`` (0/1), ``lost`` (0/1: the run found its scans no
longer fit the map, ``localize.lost_*``; NaN for a trajectory from another localizer, or a run from before the
test), ``time_to_lost_s`` and, for global initialization,
``global_success`` (0/1); with a truth and a door map, ``door_state_error_mean`` / ``_max`` (rad, over the doors
observed within ``evaluate.door_state_window_s``) and ``door_state_error_all_mean`` (rad, over all matched doors at
every update, observed or not).
Per door map with a truth: ``door_precision``, ``door_recall``, ``door_hinge_error_mean`` (m),
``door_length_error_mean`` (m, absolute), ``door_range_error_mean`` (rad), ``doors_detected``, ``doors_truth``.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, EvaluateConfig
from doorbatch.errors import PipelineError
from doorbatch.geometry.se2 import compose, interpolate_poses
from doorbatch.io.mapdir import ODOMETRY_FRAME_SOURCES
from doorbatch.io.sim_truth import SimTruth
from doorbatch.maps import DoorSet
from doorbatch.pipeline.evaluate.door_map import score_doors, truth_doors
from doorbatch.pipeline.evaluate.door_state_error import door_state_errors
from doorbatch.pipeline.evaluate.localization_success import ConvergenceCheck, global_success
from doorbatch.pipeline.evaluate.trajectory_metrics import (
    Alignment,
    TrajectoryErrors,
    statistics,
    trajectory_errors,
)
from doorbatch.pipeline.localize.door_geometry import hinge_unknown
from doorbatch.pipeline.localize.result import LocalizationResult

FloatArray = npt.NDArray[np.float64]
Int64Array = npt.NDArray[np.int64]


@dataclass(frozen=True)
class ReferenceTrajectory:
    """Reference poses (ground truth or SLAM): (N,) stamps in ns, (N, 3) x, y, yaw in the map frame; the
    warnings of reading them from their log (e.g. repaired CARMEN stamps). ``independent`` is False where the
    reference is the log's odometry moved rigidly (``Recording.reference_is_odometry``: a raw CARMEN log's laser
    poses): a run's own such reference gets no APE, RPE or global success, which would score the odometry."""

    stamps_ns: Int64Array
    pose: FloatArray
    warnings: tuple[str, ...] = ()
    independent: bool = True


@dataclass(frozen=True)
class DoorStateTable:
    """door_states.parquet of one run as arrays (one row per update and door)."""

    stamps_ns: Int64Array
    door_id: npt.NDArray[np.int32]
    angle: FloatArray
    observed: npt.NDArray[np.bool_]


@dataclass(frozen=True)
class RunTables:
    """One localization run (a ``doorbatch localize`` run directory, or a result in memory).

    Attributes:
        name: the run's label in the report (e.g. ``loc_closed/rbpf``); log, method: as in trajectory.parquet.
        stamps_ns, pose: the estimated trajectory; init: ``reference``, ``global`` or ``X,Y,YAW``.
        converged_ns: first stamp counted as converged (None: never); ambiguous: as the run reported.
        lost_ns: stamps at which the run found itself lost (its scans stopped fitting the map).
        door_states: the RBPF's door angles (None for MCL); map_doors: the map's doors they refer to.
        reference, truth: the run's own reference trajectory and simulator truth, when known.
        params: the sweep point of an experiment (goes into metrics.parquet's params column).
        map_path: the map the run localized on, when known.
    """

    name: str
    log: str
    method: str
    stamps_ns: Int64Array
    pose: FloatArray
    init: str = "reference"
    converged_ns: int | None = None
    ambiguous: bool = False
    door_states: DoorStateTable | None = None
    map_doors: DoorSet | None = None
    reference: ReferenceTrajectory | None = None
    truth: SimTruth | None = None
    params: dict[str, Any] = field(default_factory=dict)
    map_path: str | None = None
    lost_ns: tuple[int, ...] | None = None  # stamps at which the run found itself lost; None: not known
    # False for another localizer's trajectory (TUM, a pose topic): it says nothing of convergence or ambiguity,
    # so converged, time_to_converge_s and ambiguous are NaN, not "converged at its first pose".
    convergence_reported: bool = True
    # The resolved config the run was made with (its manifest's ``config``); None: not known (a run in memory,
    # another localizer's trajectory).
    config: dict[str, Any] | None = None


def with_setups_told_apart(runs: Sequence[RunTables], max_config_keys: int) -> list[RunTables]:
    """Runs outside an experiment (no params) of one log and method that differ in ``--init``, in their map or in
    their resolved config (seeds aside) get those as params, so that the summary does not average them as if they
    were seeds of one setup. A config difference is told by :func:`config_params`: the keys, among those that differ
    between the runs, where the run leaves doorbatch's defaults (at most ``max_config_keys`` of them)."""
    setups: dict[tuple[str, str], set[tuple[str, str | None, str | None]]] = defaultdict(set)
    defaults = _flat_config(DoorbatchConfig().as_dict())
    # a key an older manifest lacks (a newer doorbatch added it) took its default then
    flat = {id(run): None if run.config is None else {**defaults, **_flat_config(run.config)} for run in runs}
    for run in runs:
        if not run.params:
            setups[(run.log, run.method)].add((run.init, run.map_path, _config_key(flat[id(run)])))
    differing = {key: _differing_keys([flat[id(r)] for r in runs if not r.params and (r.log, r.method) == key])
                 for key, seen in setups.items() if len({c for *_, c in seen}) > 1}
    maps = {r.map_path for r in runs if r.map_path is not None}
    label = _short_labels(maps)
    out = []
    for run in runs:
        seen = setups.get((run.log, run.method), set())
        if run.params or len(seen) < 2:
            out.append(run)
            continue
        params: dict[str, Any] = {}
        if len({init for init, _, _ in seen}) > 1:
            params["init"] = run.init
        if len({m for _, m, _ in seen}) > 1:
            params["map"] = label.get(run.map_path) if run.map_path is not None else None
        if (run.log, run.method) in differing:
            params.update(config_params(flat[id(run)], differing[(run.log, run.method)], defaults, max_config_keys))
        out.append(replace(run, params=params))
    return out


# Config keys that do not tell setups apart: the seed (runs that differ only in it are averaged) and the method
# (a row of its own already; ``--method`` does not change ``localize.method``).
_NOT_A_SETUP = ("seed", "localize.method")


def _flat_config(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    """A config tree as dotted keys (``localize.sigma_hit_m``) → values, without the keys of :data:`_NOT_A_SETUP`
    (a ``seed`` at any level)."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        path = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flat_config(value, f"{path}."))
        elif key != "seed" and path not in _NOT_A_SETUP:
            flat[path] = value
    return flat


def _config_key(flat: dict[str, Any] | None) -> str | None:
    """A flat config as canonical text (None: not known): equal configs, equal keys."""
    return None if flat is None else params_json(flat)


def _differing_keys(configs: Sequence[dict[str, Any] | None]) -> list[str]:
    """The keys whose value is not the same in all known ``configs`` (missing counts as a value), sorted."""
    known = [c for c in configs if c is not None]
    keys = sorted({k for c in known for k in c})
    return [k for k in keys if len({params_json({"v": c.get(k)}) for c in known}) > 1]


def config_params(flat: dict[str, Any] | None, differing: Sequence[str], defaults: dict[str, Any],
                  max_keys: int) -> dict[str, Any]:
    """What tells a run's config apart in the params column: each of the ``differing`` keys where it leaves the
    ``defaults`` (``{"localize.laser_model": "likelihood_field_prob"}``); ``{"config": "default"}`` where it leaves
    none; ``{"config": "unknown"}`` for a run whose config is not known. Beyond ``max_keys`` keys, the first of
    them and ``config`` = a short hash of the config with the count of keys left out, so that two configs never
    share a label. Two runs whose configs differ get different params (one of them leaves the defaults at a key
    where they differ)."""
    if flat is None:
        return {"config": "unknown"}
    own = {k: flat.get(k) for k in differing if params_json({"v": flat.get(k)}) != params_json({"v": defaults.get(k)})}
    if not own:
        return {"config": "default"}
    if len(own) <= max_keys:
        return own
    shown = dict(list(own.items())[:max_keys])
    digest = hashlib.sha256(params_json(flat).encode()).hexdigest()[:8]
    return {**shown, "config": f"{digest} (+{len(own) - max_keys} keys)"}


def _short_labels(paths: set[str]) -> dict[str, str]:
    """A name for each map in the report: its folder (``.../site_a/map/map.yaml`` → ``map``), with parent folders
    added until the names differ (``site_a/map``), so that labels do not depend on where the files live."""
    parts = {p: Path(p).parent.parts if Path(p).name == "map.yaml" else Path(p).parts for p in paths}
    depth = 1
    while True:
        names = {p: "/".join(parts[p][-depth:]) for p in paths}
        if len(set(names.values())) == len(paths) or depth >= max((len(v) for v in parts.values()), default=1):
            return names
        depth += 1


def run_tables_from_result(result: LocalizationResult, *, name: str | None = None, init: str = "reference",
                           map_doors: DoorSet | None = None, reference: ReferenceTrajectory | None = None,
                           truth: SimTruth | None = None, params: dict[str, Any] | None = None) -> RunTables:
    """A run in memory (``localize``'s result) as :class:`RunTables`, without writing a run directory; its door
    states are the rows door_states.parquet would hold (:func:`~doorbatch.io.rundir.door_state_columns`: the
    updates while standing still among them)."""
    from doorbatch.io.rundir import door_state_columns

    cols = door_state_columns(result)
    states = None if result.door_mean.shape[1] == 0 else DoorStateTable(
        np.asarray(cols["stamp_ns"], dtype=np.int64), np.asarray(cols["door_id"], dtype=np.int32),
        np.asarray(cols["angle"], dtype=np.float64), np.asarray(cols["observed"], dtype=bool))
    return RunTables(name or f"{result.log}/{result.method}", result.log, result.method, result.stamps_ns,
                     result.pose, init, result.converged_ns, result.ambiguous, states, map_doors, reference, truth,
                     dict(params or {}), lost_ns=tuple(result.lost_ns))


@dataclass(frozen=True)
class MapTables:
    """A door map to score: its doors and the simulator truth of its mapping passes."""

    name: str
    doors: DoorSet
    truth: SimTruth | None = None
    params: dict[str, Any] = field(default_factory=dict)
    # "em" when doors.parquet holds the EM stage's doors (moved and never moved), else "grid" (moved only).
    source: str = "grid"
    # The poses the map was built from (its manifest's pose_source): scanmatch and odometry maps lie in their first
    # pass's odometry frame, not a truth's world frame.
    pose_source: str | None = None
    # (D,) doors.parquet's moved (seen at two or more distinguishable angles); None: not known (all taken as moved).
    moved: npt.NDArray[np.bool_] | None = None


@dataclass(frozen=True)
class MetricRow:
    """One row of metrics.parquet (DESIGN schema); ``params`` is written as JSON."""

    run: str
    log: str
    method: str
    metric: str
    value: float
    unit: str
    params: dict[str, Any] = field(default_factory=dict)


def params_json(params: dict[str, Any]) -> str:
    """The params column's JSON (sorted keys, compact)."""
    return json.dumps(params, sort_keys=True, separators=(",", ":"), default=str)


def metric_columns(rows: Sequence[MetricRow]) -> dict[str, list[Any]]:
    """metrics.parquet's columns (DESIGN schema) of ``rows``."""
    return {"run": [r.run for r in rows], "log": [r.log for r in rows], "method": [r.method for r in rows],
            "metric": [r.metric for r in rows], "value": [float(r.value) for r in rows],
            "unit": [r.unit for r in rows], "params": [params_json(r.params) for r in rows]}


@dataclass(frozen=True)
class ErrorSeries:
    """A run's localization error over time and along the corridor (paper 000 Figs. 5–7)."""

    run: str
    log: str
    method: str
    params: dict[str, Any]
    t_s: FloatArray  # since the run's first update
    x_ref_m: FloatArray  # reference x (the corridor direction)
    position_error_m: FloatArray
    yaw_error_rad: FloatArray


@dataclass(frozen=True)
class DoorStateSeries:
    """A run's mean absolute door-angle error over the recently observed doors, per update."""

    run: str
    log: str
    method: str
    t_s: FloatArray
    error_rad: FloatArray


@dataclass(frozen=True)
class AlongCorridor:
    """Position error binned along x and averaged over the runs of one (log, method): mean and std."""

    log: str
    method: str
    x_m: FloatArray
    mean_error_m: FloatArray
    std_error_m: FloatArray
    runs: int


@dataclass(frozen=True)
class SuccessCurve:
    """Global localization success rate against the particle count, for one (log, method)."""

    log: str
    method: str
    particles: FloatArray
    success_rate: FloatArray
    runs: npt.NDArray[np.int64]


@dataclass(frozen=True)
class Evaluation:
    """Everything a report shows: the metric rows and the data of each plot."""

    metrics: list[MetricRow]
    errors: list[ErrorSeries]
    door_states: list[DoorStateSeries]
    along_corridor: list[AlongCorridor]
    success: list[SuccessCurve]
    title: str = "doorbatch evaluation"
    left_out: tuple[str, ...] = ()  # batch steps that failed or were blocked: no rows of them (doorbatch run)
    warnings: tuple[str, ...] = ()  # what the metrics leave out or cannot tell, and why (for the manifest)

    def value(self, run: str, metric: str) -> float:
        """The value of one metric of one run (NaN when absent)."""
        return next((r.value for r in self.metrics if r.run == run and r.metric == metric), math.nan)

    def with_title(self, title: str, left_out: Sequence[str] = ()) -> Evaluation:
        """The same evaluation under another title, naming the steps whose results it lacks."""
        return replace(self, title=title, left_out=tuple(left_out))


def _stat_rows(run: RunTables, prefix: str, errors: FloatArray, unit: str, scale: float) -> list[MetricRow]:
    return [MetricRow(run.name, run.log, run.method, f"{prefix}_{k}", v * scale, unit, run.params)
            for k, v in statistics(errors).items()]


def _trajectory_rows(run: RunTables, errs: TrajectoryErrors, cfg: EvaluateConfig) -> list[MetricRow]:
    scale = math.degrees(1.0) if cfg.angle_unit == "deg" else 1.0
    rows = [*_stat_rows(run, "ape_trans", errs.ape_m, "m", 1.0),
            *_stat_rows(run, "ape_rot", errs.ape_rad, cfg.angle_unit, scale),
            *_stat_rows(run, "rpe_trans", errs.rpe_m, "m", 1.0),
            *_stat_rows(run, "rpe_rot", errs.rpe_rad, cfg.angle_unit, scale)]
    rows.append(MetricRow(run.name, run.log, run.method, "associated_poses", float(len(errs.ape_m)), "count",
                          run.params))
    rows.append(MetricRow(run.name, run.log, run.method, "rpe_pairs", float(len(errs.rpe_m)), "count", run.params))
    return rows


def reference_at(ref: ReferenceTrajectory, stamps_ns: Int64Array, max_gap_ns: int) -> ReferenceTrajectory:
    """``ref`` interpolated at ``stamps_ns`` (SE(2): positions linearly, the heading along the shorter arc) where
    reference poses at most ``max_gap_ns`` apart bracket the stamp (``evaluate.reference_at_run_stamps``)."""
    pose, valid = interpolate_poses(ref.stamps_ns, ref.pose, stamps_ns, max_gap_ns)
    return replace(ref, stamps_ns=np.asarray(stamps_ns, dtype=np.int64)[valid], pose=pose[valid])


def _sparse_match_note(run: RunTables, matched: int, ref: ReferenceTrajectory, cfg: EvaluateConfig) -> str:
    """The warning for a run of which few poses found a reference pose: how many, and why it may be so (a
    reference whose poses lie further apart than twice the tolerance: the tolerance that pairs every pose)."""
    note = (f"run {run.name}: only {matched} of its {len(run.stamps_ns)} poses have a reference pose within "
            f"{cfg.max_time_diff_s} s (evaluate.max_time_diff_s, evo --t_max_diff); its metrics stand on those")
    period_s = float(np.median(np.diff(ref.stamps_ns))) / 1e9 if len(ref.stamps_ns) > 1 else 0.0
    if period_s > 2.0 * cfg.max_time_diff_s:
        return (f"{note}. The reference's poses are {1e3 * period_s:.0f} ms apart: --set "
                "evaluate.reference_at_run_stamps=true scores every pose against the reference interpolated at its "
                f"stamp (evaluate.max_time_diff_s={period_s / 2:.3g} pairs every pose with its nearest, up to that far "
                "off in time)")
    return f"{note}. Stamps on another clock than the reference's? (evaluate.t_offset_s, evo --t_offset)"


def _coverage_note(run: RunTables, ref: ReferenceTrajectory, cfg: EvaluateConfig) -> list[str]:
    """A warning when the run's poses span less than ``min_time_covered_share`` of the reference's time span: its
    metrics describe that part of the log only."""
    ref_s = float(ref.stamps_ns[-1] - ref.stamps_ns[0]) / 1e9 if len(ref.stamps_ns) > 1 else 0.0
    run_s = float(run.stamps_ns[-1] - run.stamps_ns[0]) / 1e9
    if not ref_s > 0.0 or run_s >= cfg.min_time_covered_share * ref_s:
        return []
    return [f"run {run.name}: its {len(run.stamps_ns)} pose(s) span {run_s:.1f} s of the reference's {ref_s:.1f} s "
            "(evaluate.min_time_covered_share): its metrics describe that part only (a robot that stood still for the "
            "rest, which AMCL's update thresholds leave without poses; odometry that never moved; a run cut short)"]


def shifted_in_time(run: RunTables, offset_ns: int) -> RunTables:
    """``run`` with every time it holds moved by ``offset_ns`` (evo's ``--t_offset``: the estimate's stamps)."""
    if not offset_ns:
        return run
    states = run.door_states
    return replace(run, stamps_ns=run.stamps_ns + offset_ns,
                   converged_ns=None if run.converged_ns is None else run.converged_ns + offset_ns,
                   lost_ns=None if run.lost_ns is None else tuple(t + offset_ns for t in run.lost_ns),
                   door_states=None if states is None else replace(states, stamps_ns=states.stamps_ns + offset_ns))


def _frame_hint(run: RunTables, errs: TrajectoryErrors, ref: ReferenceTrajectory, cfg: EvaluateConfig) -> list[str]:
    """A warning when the run's APE is mostly a rigid offset (``frame_hint_min_ape_m``, ``frame_hint_ratio``):
    the run and its reference are in different frames, and ``--align se2`` scores it in the reference's."""
    rmse = float(np.sqrt(np.mean(errs.ape_m**2)))
    if not rmse > cfg.frame_hint_min_ape_m or len(errs.ape_m) < 3:
        return []
    try:
        aligned = trajectory_errors(run.stamps_ns, run.pose, ref.stamps_ns, ref.pose, max_diff_s=cfg.max_time_diff_s,
                                    align=Alignment.SE2, rpe_delta_m=cfg.rpe_delta_m)
    except PipelineError:  # a robot that stood still: no rigid motion to fit, no hint to give
        return []
    rmse_aligned = float(np.sqrt(np.mean(aligned.ape_m**2)))
    if rmse_aligned > cfg.frame_hint_ratio * rmse:
        return []
    x, y, yaw = aligned.alignment
    head = (f"run {run.name}: APE RMSE {rmse:.2f} m, {rmse_aligned:.3f} m after a rigid motion ({x:.2f} m, {y:.2f} m, "
            f"{math.degrees(yaw):.1f}°): ")
    if run.init == "global":  # a lock on a similar place is a rigid offset too, and aligning it away hides it
        return [head + "a global start that locked on the wrong one of two similar places (its global_success says "
                "so), or a map in another frame than the reference (one built from scanmatch or odometry poses); "
                "--align se2 is right only for the latter"]
    return [head + "the run is in another frame than its reference (a map built from scanmatch or odometry poses lies "
            "in its first pass's odometry frame); --align se2 scores it in the reference's"]


def _convergence_rows(run: RunTables, reference: ReferenceTrajectory | None, cfg: EvaluateConfig,
                      alignment: FloatArray | None = None) -> list[MetricRow]:
    """Convergence, loss and (a global start) success rows; ``alignment``: the rigid motion ``--align se2`` put
    the run's poses through for its APE (:class:`~.trajectory_metrics.TrajectoryErrors`), so that success is
    judged in the same frame (a map built from scan matching is in its odometry's frame, not the reference's)."""
    t0 = int(run.stamps_ns[0])
    told = run.convergence_reported
    after = math.nan if run.converged_ns is None else (run.converged_ns - t0) / 1e9
    rows = [MetricRow(run.name, run.log, run.method, "converged",
                      float(run.converged_ns is not None) if told else math.nan, "bool", run.params),
            MetricRow(run.name, run.log, run.method, "time_to_converge_s", after, "s", run.params),
            MetricRow(run.name, run.log, run.method, "ambiguous", float(run.ambiguous) if told else math.nan, "bool",
                      run.params),
            MetricRow(run.name, run.log, run.method, "lost",
                      math.nan if run.lost_ns is None else float(bool(run.lost_ns)), "bool", run.params),
            MetricRow(run.name, run.log, run.method, "time_to_lost_s",
                      (run.lost_ns[0] - t0) / 1e9 if run.lost_ns else math.nan, "s", run.params)]
    if run.init == "global" and reference is not None:
        check = ConvergenceCheck(cfg.global_success_window_s, cfg.global_success_xy_m,
                                 math.radians(cfg.global_success_yaw_deg), cfg.global_success_max_reference_gap_s)
        pose = run.pose if alignment is None else compose(np.broadcast_to(alignment, run.pose.shape), run.pose)
        ok = global_success(run.stamps_ns, pose, run.converged_ns, reference.stamps_ns, reference.pose, check)
        rows.append(MetricRow(run.name, run.log, run.method, "global_success", float(ok), "bool", run.params))
    return rows


def _unknown_doors_note(run: RunTables) -> str | None:
    """A warning when the run's door states name doors its map's doors.parquet lacks (a run scored against a map
    rebuilt or renumbered since): those are not scored; None when every door_id is the map's."""
    if run.door_states is None or run.map_doors is None:
        return None
    unknown = sorted(set(np.unique(run.door_states.door_id).tolist()) - set(run.map_doors.ids.tolist()))
    if not unknown:
        return None
    shown = ", ".join(str(i) for i in unknown[:8]) + (", …" if len(unknown) > 8 else "")
    return (f"run {run.name}: its door states name door_id {shown}, which its map's doors.parquet lacks (a map "
            "rebuilt or renumbered since the run?): those doors are not scored")


PARTLY_OUTSIDE_SHARE = 0.05  # of a run's updates outside its truth's log span: the truth is likely another log's


def _truth_span_note(run: RunTables, truth: SimTruth) -> tuple[str | None, bool]:
    """A warning where the run's updates lie outside the time span of the truth's log (``start_ns`` … ``end_ns``),
    and whether its door states are scored. Wholly outside: not scored, its door angles are another log's
    (``--world`` given the mapping log's truth for a localization run had scored the doors against the mapping
    passes' angles, without a word). More than :data:`PARTLY_OUTSIDE_SHARE` outside: scored, with a warning (a
    truth of a log whose sim time also starts near 0, hAL's relaunched simulator, scored 0.56 rad for a 0.005 rad
    run). (None, True) where the spans agree."""
    if truth.end_ns <= truth.start_ns or not run.stamps_ns.size:
        return None, True
    first, last = int(run.stamps_ns[0]), int(run.stamps_ns[-1])
    log = truth.files.get("log", "another log")
    span = f"{truth.start_ns / 1e9:.1f}-{truth.end_ns / 1e9:.1f} s"
    if first > truth.end_ns or last < truth.start_ns:
        return (f"run {run.name}: door states not scored: the truth's log ({log}) spans {span} and the run's updates "
                f"{first / 1e9:.1f}-{last / 1e9:.1f} s, so its door angles are another log's (give --world the truth "
                f"of the log {run.log} was localized in)"), False
    outside = float(np.mean((run.stamps_ns < truth.start_ns) | (run.stamps_ns > truth.end_ns)))
    if outside <= PARTLY_OUTSIDE_SHARE:
        return None, True
    return (f"run {run.name}: {100 * outside:.0f} % of its updates lie outside the time span of the truth's log "
            f"({log}, {span}): its door states are scored against angles that may be another log's (give --world "
            f"the truth of the log {run.log} was localized in)"), True


def _door_state_part(run: RunTables, truth: SimTruth | None, cfg: EvaluateConfig
                     ) -> tuple[list[MetricRow], list[DoorStateSeries]]:
    """Door-state rows (over the recently observed doors, and over all matched doors) and the plotted series."""
    if truth is None or run.door_states is None or run.map_doors is None or not len(run.map_doors):
        return [], []
    s, window_ns = run.door_states, int(cfg.door_state_window_s * 1e9)
    series = door_state_errors(s.stamps_ns, s.door_id, s.angle, s.observed, run.map_doors, truth,
                               cfg.door_match_max_hinge_m, window_ns)
    every = door_state_errors(s.stamps_ns, s.door_id, s.angle, s.observed, run.map_doors, truth,
                              cfg.door_match_max_hinge_m, window_ns, observed_only=False)
    rows = []
    if series.stamps_ns.size:
        rows += [MetricRow(run.name, run.log, run.method, "door_state_error_mean", float(np.mean(series.error_rad)),
                           "rad", run.params),
                 MetricRow(run.name, run.log, run.method, "door_state_error_max", float(np.max(series.error_rad)),
                           "rad", run.params)]
    if every.stamps_ns.size:  # also where no door was ever observed: what the observed-only mean cannot show
        rows.append(MetricRow(run.name, run.log, run.method, "door_state_error_all_mean",
                              float(np.mean(every.error_rad)), "rad", run.params))
    if series.stamps_ns.size == 0:
        return rows, []
    t0 = int(run.stamps_ns[0])
    return rows, [DoorStateSeries(run.name, run.log, run.method, (series.stamps_ns - t0) / 1e9, series.error_rad)]


def _map_rows(door_map: MapTables, truth: SimTruth | None, cfg: DoorbatchConfig) -> tuple[list[MetricRow], list[str]]:
    """A door map's rows against the truth, and warnings. A truth without ``leaf_observations`` (written by hand)
    does not tell which doors the laser saw move: every truth door is then one the map should have (the recall of
    a grid map, which finds moved doors only, is a lower bound), and recall over moved and never-moved doors is
    not given."""
    if truth is None:
        return ([MetricRow(door_map.name, "", "map", "doors_detected", float(len(door_map.doors)), "count",
                           door_map.params)],
                [f"map {door_map.name}: no mapping truth (--world FILE.truth.yaml, or <log stem>.truth.yaml beside its "
                 "logs): only doors_detected is reported"])
    truth_set, moved = truth_doors(truth, math.radians(cfg.doors.min_opening_deg))
    max_m = cfg.evaluate.door_match_max_hinge_m
    warnings = []
    every_door = truth.leaf_observations is None or door_map.source == "em"
    if truth.leaf_observations is None:
        warnings.append(f"map {door_map.name}: the truth has no leaf_observations (which doors the laser saw at two "
                        f"angles): its doors are scored by position, all {len(moved)} counted as doors the map should "
                        "have; recall over moved and never-moved doors cannot be told")
    # the truth doors recall counts (doors_truth): those the laser saw at two angles; every door for a truth that
    # does not say, and for EM, which also finds doors that never moved (paper 001)
    counted = np.ones(len(moved), dtype=bool) if every_door else moved
    # a door that never moved and was seen closed shows no hinge: the map's hinge may be its free end
    unknown = None if door_map.moved is None else hinge_unknown(
        ~door_map.moved, door_map.doors, math.radians(cfg.localize.door_angle_margin_deg))
    score = score_doors(door_map.doors, truth_set, counted, max_m, unknown)
    extra = []
    if truth.leaf_observations is not None and door_map.source == "em":
        found = np.zeros(len(moved), dtype=bool)
        found[[j for _, j in score.matches]] = True
        extra = [("door_recall_moved", _fraction(found[moved]), "ratio"),
                 ("door_recall_never_moved", _fraction(found[~moved]), "ratio"),
                 ("doors_truth_never_moved", float((~moved).sum()), "count")]

    def mean(a: FloatArray) -> float:
        return float(np.mean(np.abs(a))) if a.size else math.nan

    if door_map.pose_source in ODOMETRY_FRAME_SOURCES and len(door_map.doors) and not score.precision >= 0.5:
        warnings.append(f"map {door_map.name}: built from {door_map.pose_source} poses, it lies in its first pass's "
                        f"odometry frame, and its doors match the truth's world frame poorly (precision "
                        f"{score.precision:.2f}): map from the reference (--pose-source reference) to score it, or "
                        "expect the frames to differ by the first pass's start pose")
    values = [("door_precision", score.precision, "ratio"), ("door_recall", score.recall, "ratio"),
              ("door_hinge_error_mean", mean(score.hinge_error_m), "m"),
              ("door_length_error_mean", mean(score.length_error_m), "m"),
              ("door_range_error_mean", mean(score.range_error_rad), "rad"),
              ("doors_detected", float(len(door_map.doors)), "count"), ("doors_truth", float(counted.sum()), "count"),
              *extra]
    return [MetricRow(door_map.name, "", "map", k, float(v), u, door_map.params) for k, v, u in values], warnings


def _fraction(found: npt.NDArray[np.bool_]) -> float:
    """Share of True (NaN when there is nothing to find)."""
    return float(found.mean()) if found.size else math.nan


def along_corridor(series: Sequence[ErrorSeries], bin_m: float) -> list[AlongCorridor]:
    """Per (log, method): position error binned by reference x (width ``bin_m``), mean and std over the
    runs' per-bin means (paper 000 Figs. 5–7 average 10 runs)."""
    groups: dict[tuple[str, str], list[ErrorSeries]] = defaultdict(list)
    for s in series:
        groups[(s.log, s.method)].append(s)
    curves = []
    for (log_name, method), members in groups.items():
        x_all = np.concatenate([m.x_ref_m for m in members])
        if x_all.size == 0:
            continue
        lo = math.floor(float(x_all.min()) / bin_m)
        n_bins = math.floor(float(x_all.max()) / bin_m) - lo + 1
        per_run = np.full((len(members), n_bins), np.nan)
        for r, m in enumerate(members):
            idx = np.floor(m.x_ref_m / bin_m).astype(np.int64) - lo
            sums = np.bincount(idx, m.position_error_m, n_bins)
            counts = np.bincount(idx, minlength=n_bins)
            per_run[r, counts > 0] = sums[counts > 0] / counts[counts > 0]
        seen = np.isfinite(per_run).any(axis=0)
        x = (np.arange(n_bins) + lo + 0.5) * bin_m
        with np.errstate(invalid="ignore"):
            curves.append(AlongCorridor(log_name, method, x[seen], np.nanmean(per_run[:, seen], axis=0),
                                        np.nanstd(per_run[:, seen], axis=0), len(members)))
    return curves


def success_curves(rows: Sequence[MetricRow]) -> list[SuccessCurve]:
    """Per (log, method): the fraction of ``global_success`` runs at each ``params["particles"]``."""
    groups: dict[tuple[str, str], dict[float, list[float]]] = defaultdict(lambda: defaultdict(list))
    for r in rows:
        if r.metric == "global_success" and "particles" in r.params:
            groups[(r.log, r.method)][float(r.params["particles"])].append(r.value)
    curves = []
    for (log_name, method), by_n in groups.items():
        ns = sorted(by_n)
        curves.append(SuccessCurve(log_name, method, np.array(ns), np.array([np.mean(by_n[n]) for n in ns]),
                                   np.array([len(by_n[n]) for n in ns], dtype=np.int64)))
    return curves


def evaluate_runs(runs: Sequence[RunTables], config: DoorbatchConfig, *,
                  reference: ReferenceTrajectory | None = None, truth: SimTruth | None = None,
                  maps: Sequence[MapTables] = ()) -> Evaluation:
    """Metrics and plot data of localization runs and door maps (see the module docstring).

    A run with no reference gets only its convergence metrics, and so does a run whose own reference is not
    independent (its log's odometry moved rigidly, :attr:`ReferenceTrajectory.independent`; a warning says so);
    a ``reference`` given here is used whatever it is. A run whose stamps match no reference pose within
    ``evaluate.max_time_diff_s`` raises.

    Raises:
        PipelineError: a run and its reference have no pose within the time tolerance.
    """
    cfg = config.evaluate
    rows: list[MetricRow] = []
    series: list[ErrorSeries] = []
    door_series: list[DoorStateSeries] = []
    warnings: list[str] = []
    for run in with_setups_told_apart(runs, cfg.params_max_config_keys):
        if len(run.stamps_ns) == 0:
            raise PipelineError(f"run {run.name}: empty trajectory")
        run = shifted_in_time(run, round(cfg.t_offset_s * 1e9))
        ref = reference if reference is not None else run.reference
        if reference is None and ref is not None and not ref.independent:
            warnings.append(f"run {run.name}: its log's reference is the odometry moved rigidly, no independent "
                            "reference: APE, RPE and global success are not reported (convergence metrics only); "
                            "give --reference for a truth")
            ref = None
        alignment = None
        if ref is not None:
            warnings += _coverage_note(run, ref, cfg)
        if ref is not None and cfg.reference_at_run_stamps:
            ref = reference_at(ref, run.stamps_ns, round(cfg.global_success_max_reference_gap_s * 1e9))
        if ref is not None:
            try:
                errs = trajectory_errors(run.stamps_ns, run.pose, ref.stamps_ns, ref.pose,
                                         max_diff_s=cfg.max_time_diff_s, align=Alignment(cfg.align),
                                         rpe_delta_m=cfg.rpe_delta_m, rpe_all_pairs=cfg.rpe_all_pairs,
                                         rpe_rel_delta_tol=cfg.rpe_rel_delta_tol)
            except PipelineError as err:
                raise PipelineError(f"run {run.name}: {err}") from err
            rows += _trajectory_rows(run, errs, cfg)
            if len(errs.ape_m) < cfg.min_associated_share * len(run.stamps_ns):
                warnings.append(_sparse_match_note(run, len(errs.ape_m), ref, cfg))
            alignment = errs.alignment if Alignment(cfg.align) is Alignment.SE2 else None
            if alignment is not None:
                rows += [MetricRow(run.name, run.log, run.method, f"alignment_{k}", float(v), u, run.params)
                         for k, v, u in zip(("x", "y", "yaw"), alignment, ("m", "m", "rad"), strict=True)]
            else:
                warnings += _frame_hint(run, errs, ref, cfg)
            series.append(ErrorSeries(run.name, run.log, run.method, run.params,
                                      (errs.stamps_ns - int(run.stamps_ns[0])) / 1e9, errs.reference[:, 0],
                                      errs.ape_m, errs.ape_rad))
        rows += _convergence_rows(run, ref, cfg, alignment)
        run_truth = truth if truth is not None else run.truth
        if run_truth is not None and run.door_states is not None:
            note, scored = _truth_span_note(run, run_truth)
            warnings += [note] if note else []
            run_truth = run_truth if scored else None
        if run_truth is not None and (note := _unknown_doors_note(run)):
            warnings.append(note)
        state_rows, state_series = _door_state_part(run, run_truth, cfg)
        rows += state_rows
        door_series += state_series
    for door_map in maps:
        map_rows, map_warnings = _map_rows(door_map, truth if truth is not None else door_map.truth, config)
        rows += map_rows
        warnings += map_warnings
    return Evaluation(rows, series, door_series, along_corridor(series, cfg.along_x_bin_m), success_curves(rows),
                      warnings=tuple(warnings))



SUMMARY_METRICS = ("ape_trans_rmse", "ape_trans_max", "ape_rot_rmse", "rpe_trans_rmse", "rpe_rot_rmse",
                   "time_to_converge_s", "global_success", "lost", "door_state_error_mean",
                   "door_state_error_all_mean")
MAP_METRICS = ("door_precision", "door_recall", "door_recall_moved", "door_recall_never_moved",
               "door_hinge_error_mean", "door_length_error_mean", "door_range_error_mean")
# Door pose experiments (paper 003 Tables I and II; rows from doorbatch.pipeline.doorpose.experiment).
DOORPOSE_METRICS = ("door_pose_error_mean", "door_pose_error_std", "positioning_error_mean", "positioning_error_std",
                    "reached_fraction", "failures", "handle_side_accuracy", "z_test_p_vs_ransac",
                    "z_test_p_vs_continuous")


@dataclass(frozen=True)
class SummaryTable:
    """A table of the report: column names, units, and rows of (labels..., values...)."""

    label_columns: tuple[str, ...]
    value_columns: tuple[str, ...]
    units: tuple[str, ...]
    rows: list[tuple[tuple[str, ...], tuple[float, ...]]]


def _label(params: dict[str, Any]) -> str:
    return ", ".join(f"{k}={v}" for k, v in sorted(params.items()) if k != "seed" and v is not None)


def _sort_key(params: dict[str, Any]) -> tuple[tuple[str, int, float, str], ...]:
    """Sweep points in numeric order (1,000 before 5,000 before 10,000), seeds left out."""
    return tuple((k, 0, float(v), "") if isinstance(v, int | float) else (k, 1, 0.0, str(v))
                 for k, v in sorted(params.items()) if k != "seed")


def summary_table(evaluation: Evaluation, metrics: Sequence[str] = SUMMARY_METRICS, method_map: bool = False
                  ) -> SummaryTable:
    """Mean of each metric per (log, method, sweep point without the seed), over the runs (seeds) there."""
    keep = [r for r in evaluation.metrics if r.metric in metrics and ((r.method == "map") == method_map)]
    groups: dict[tuple[str, str, str], dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    runs: dict[tuple[str, str, str], set[str]] = defaultdict(set)
    units: dict[str, str] = {}
    order: dict[tuple[str, str, str], tuple[Any, ...]] = {}
    for r in keep:
        key = (r.log if not method_map else r.run, r.method, _label(r.params))
        order.setdefault(key, (key[0], key[1], *_sort_key(r.params)))
        groups[key][r.metric].append(r.value)
        runs[key].add(r.run)
        units[r.metric] = r.unit
    present = tuple(m for m in metrics if m in units)
    rows: list[tuple[tuple[str, ...], tuple[float, ...]]] = []
    for key in sorted(groups, key=order.__getitem__):
        values = tuple(float(np.nanmean(groups[key][m])) if groups[key].get(m) and np.isfinite(groups[key][m]).any()
                       else math.nan for m in present)
        rows.append(((*key, str(len(runs[key]))), values))
    first = "map" if method_map else "log"
    return SummaryTable((first, "method", "params", "runs"), present, tuple(units[m] for m in present), rows)
