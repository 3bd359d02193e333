"""``doorbatch map``: a door-augmented occupancy grid from one or more logs, each log one pass.

The stage in outline (paper 000, Sec. III)::

    recordings = load the logs
    source     = choose the pose source (reference > scan matching on odometry)
    passes     = robot poses at every scan, per pass, in one map frame
    grid       = integrate every pass into the grid, collecting dynamic points and door leaves
    doors      = doors from leaves that rotate about a common hinge; leaves removed from the static map
    (em stage) = its doors' leaves removed too (without_leaves)
"""

from __future__ import annotations

import copy
import itertools
import logging
import math
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, config_of
from doorbatch.errors import PipelineError, UsageError
from doorbatch.geometry.laser import dropouts, wraps_around
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, interpolate_poses, inverse, rotation_matrix
from doorbatch.io.preview import PreviewDoor
from doorbatch.io.recording import Recording, load_passes
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.gridmap.build import GridMapper, GridMapResult, MapScan
from doorbatch.pipeline.gridmap.doors import DetectedDoor, remove_leaves
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid, to_occupancy_map
from doorbatch.pipeline.localize.likelihood_field import FreeCells, free_cells
from doorbatch.pipeline.poses import scan_match_trajectory
from doorbatch.pipeline.poses.mount_check import mount_yaw_offsets
from doorbatch.pipeline.poses.pose_jitter import pose_jitter
from doorbatch.pipeline.time_passes import split_into_passes
from doorbatch.progress import Progress, progress_bar

FloatArray = npt.NDArray[np.float64]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PassPoses:
    """The robot (base_link) pose in the map frame at each scan of one pass; ``valid`` marks scans that
    have a pose (within the pose source's time span, no long gap)."""

    log: str
    stamps_ns: npt.NDArray[np.int64]
    poses: FloatArray
    valid: npt.NDArray[np.bool_]
    source: str


@dataclass(frozen=True)
class DoorMap:
    """What ``build_map`` returns: the static map, the doors, the poses it used, and notes."""

    static_map: OccupancyMap
    doors: list[DetectedDoor]
    passes: list[PassPoses]
    pose_source: str
    n_dynamic_points: int
    warnings: list[str] = field(default_factory=list)
    stage_seconds: dict[str, float] = field(default_factory=dict)
    grid: LogOddsGrid | None = None  # the final mapping state the static map came from

    def __repr__(self) -> str:
        """A line a notebook can show (the arrays' own repr runs to tens of thousands of characters)."""
        occ = self.static_map
        return (f"DoorMap(pose_source={self.pose_source!r}, passes={len(self.passes)}, doors={len(self.doors)}, "
                f"static_map={occ.height}x{occ.width} cells of {occ.resolution_m:g} m, "
                f"warnings={len(self.warnings)})")


def reference_coverage(rec: Recording, max_gap_s: float) -> float:
    """Share of the log's scans that get a reference pose (interpolated across gaps of at most ``max_gap_s``)."""
    if rec.reference is None or len(rec.scans.stamps_ns) == 0:
        return 0.0
    _, valid = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, rec.scans.stamps_ns,
                                 int(max_gap_s * 1e9))
    return float(np.mean(valid))


def choose_pose_source(recordings: Sequence[Recording], wanted: str, config: DoorbatchConfig
                       ) -> tuple[str, list[str]]:
    """The pose source and why another than asked for: the one asked for, or (``auto``) ``reference`` when
    every log has a reference that covers at least ``mapping.min_reference_coverage`` of its scans and is not
    its odometry again (``Recording.reference_is_odometry``), else ``scanmatch`` (a sparse pose topic, e.g.
    localization poses published only on filter updates, is not the trajectory: with it most scans would be
    skipped). ``scanmatch`` asked for matches a log without odometry at
    constant velocity (a handheld lidar).

    Raises:
        PipelineError: a log lacks what the source asked for needs, or (auto) has neither a reference nor
            odometry.
    """
    mc = config.mapping
    for rec in recordings:
        # auto too (issue #4: such a log is a clear error); matching the scans alone is a choice the user makes
        if rec.reference is None and rec.odometry is None and wanted in ("auto", "odometry", "reference"):
            raise PipelineError(f"{rec.path}: no usable pose source: no reference pose topic and no odometry "
                                "(nav_msgs/Odometry or TF odom→base_link); --pose-source scanmatch matches the scans "
                                "alone, at constant velocity")
    if wanted == "auto":
        if any(r.reference is None for r in recordings):
            return "scanmatch", []
        covered: dict[str, list[float]] = {}  # per log (the pieces of one cut by time together): scans, covered
        for r in recordings:
            n = len(r.scans)
            c = covered.setdefault(r.log_path, [0.0, 0.0])
            c[0], c[1] = c[0] + n, c[1] + n * reference_coverage(r, mc.max_pose_gap_s)
        why = [f"{path}: the reference poses cover {c / n:.0%} of the scans (< mapping.min_reference_coverage "
               f"{mc.min_reference_coverage:.0%}); poses from scan matching instead"
               for path, (n, c) in covered.items() if n and c / n < mc.min_reference_coverage]
        why += [f"{path}: poses from scan matching, as the reference is the odometry again (--pose-source "
                "reference takes it, for a corrected CARMEN log)"
                for path in dict.fromkeys(r.log_path for r in recordings if r.reference_is_odometry)]
        return ("scanmatch", why) if why else ("reference", [])
    need = {"reference": "reference", "odometry": "odometry"}.get(wanted)
    for rec in recordings:
        if need and getattr(rec, need) is None:
            raise PipelineError(f"{rec.path}: --pose-source {wanted} but the log has no {need} poses")
    return wanted, []


def reference_jitter_notes(recordings: Sequence[Recording], config: DoorbatchConfig) -> list[str]:
    """A warning per log whose reference jitters from pose to pose beyond ``mapping.reference_jitter_max_m`` /
    ``_deg`` (:func:`~doorbatch.pipeline.poses.pose_jitter.pose_jitter`, against the odometry where there is one):
    a noisy ground truth, whose scans drawn at their poses blur the map."""
    mc = config.mapping
    notes = []
    for rec in recordings:
        if rec.reference is None or rec.reference_is_odometry:
            continue
        odometry = None
        ref = rec.reference.poses
        if rec.odometry is not None:
            odometry, ok = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, rec.reference.stamps_ns)
            ref, odometry = ref[ok], odometry[ok]
        jitter = pose_jitter(ref, odometry)
        if jitter.xy_m > mc.reference_jitter_max_m or math.degrees(jitter.yaw_rad) > mc.reference_jitter_max_deg:
            notes.append(f"{rec.path}: the reference pose topic jitters from pose to pose (white noise σ ≈ "
                         f"{100 * jitter.xy_m:.1f} cm, {math.degrees(jitter.yaw_rad):.2f}°: a noisy ground truth, e.g. "
                         "Gazebo's p3d with gaussianNoise); scans drawn at its poses blur the map by about "
                         f"{100 * (jitter.yaw_rad * 5.0 + jitter.xy_m):.0f} cm at 5 m. --pose-source scanmatch matches "
                         "the scans instead")
    return notes


def pass_poses(rec: Recording, source: str, config: DoorbatchConfig) -> PassPoses:
    """Poses at the scan stamps from the chosen source (interpolated, or scan matched on odometry or, without
    odometry, at constant velocity)."""
    stamps = rec.scans.stamps_ns
    gap_ns = int(config.mapping.max_pose_gap_s * 1e9)
    if source == "reference" and rec.reference is not None:
        poses, valid = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamps, gap_ns)
        return PassPoses(rec.path, stamps, poses, valid, source)
    if source == "scanmatch":
        return _chain_scanmatch([rec], config)[0][0]
    if rec.odometry is not None:
        odom, valid = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, stamps, gap_ns)
    else:  # no odometry: every scan, for scan matching alone (_chain_scanmatch)
        odom, valid = np.zeros((stamps.shape[0], 3)), np.ones(stamps.shape[0], dtype=bool)
    return PassPoses(rec.path, stamps, odom, valid, source)


def pose_gap(end: npt.ArrayLike, start: npt.ArrayLike) -> tuple[float, float]:
    """How far pose ``start`` lies from pose ``end``: (m, degrees)."""
    step = np.asarray(start, dtype=np.float64) - np.asarray(end, dtype=np.float64)
    return float(np.hypot(step[0], step[1])), abs(math.degrees(float(wrap_angle(step[2]))))


def within_continuity(gap: tuple[float, float], config: DoorbatchConfig) -> bool:
    """Whether a gap (m, degrees) between two odometry poses is one continuous odometry frame
    (``mapping.odometry_continuity_m`` and ``_deg``)."""
    return gap[0] <= config.mapping.odometry_continuity_m and gap[1] <= config.mapping.odometry_continuity_deg


def odometry_jump(prev: Recording, nxt: Recording) -> tuple[float, float]:
    """How far ``nxt``'s odometry starts from where ``prev``'s ended: (m, degrees); inf where either has none."""
    if prev.odometry is None or nxt.odometry is None:
        return float("inf"), float("inf")
    return pose_gap(prev.odometry.poses[-1], nxt.odometry.poses[0])


def continues(prev: Recording, nxt: Recording, config: DoorbatchConfig) -> bool:
    """Whether ``nxt`` continues ``prev`` (one recording split in pieces): the next piece of the same log
    (``mapping.pass_duration_s``), or odometry that starts within ``mapping.odometry_continuity_m`` and ``_deg``
    of where ``prev``'s ended."""
    return nxt.continues_piece(prev) or within_continuity(odometry_jump(prev, nxt), config)


def time_order(recordings: Sequence[Recording], config: DoorbatchConfig) -> list[int] | None:
    """The passes' indices in the order of their first scans' times, where they were given in another order and
    either happened one after another on one clock (each pass's scans start after the one before it ends: passes
    recorded apart, or one recording's pieces that a shell glob lists as ``run_10.bag`` before ``run_2.bag``) or
    chain only in that order (a pass's odometry continues the one before it: :func:`continues`). The grid stage
    classifies each pass against the map of the passes before it (paper 000, Sec. III, an online mapper), so the
    order changes the doors: time order makes the map the same whatever order the logs are listed in. None
    otherwise: passes in time order already, or on clocks that overlap (each in sim time from 0), whose order the
    user chose.
    """
    if len(recordings) < 2 or any(len(r.scans) == 0 for r in recordings):
        return None
    given = list(range(len(recordings)))
    # On the recorder's clock (Recording.log_clock): a simulated run's stamps are sim time, which starts again with
    # every launch of the simulator, so passes recorded an hour apart may stamp in the opposite order.
    first = [r.log_clock.log_time_at(int(r.scans.stamps_ns[0])) for r in recordings]
    last = [r.log_clock.log_time_at(int(r.scans.stamps_ns[-1])) for r in recordings]
    by_time = sorted(given, key=lambda i: first[i])
    if by_time == given:
        return None
    if all(first[b] > last[a] for a, b in itertools.pairwise(by_time)):
        return by_time
    if any(r.odometry is None for r in recordings):
        return None

    def chains(order: Sequence[int]) -> bool:
        return all(continues(recordings[a], recordings[b], config) for a, b in itertools.pairwise(order))

    return by_time if chains(by_time) and not chains(given) else None


def mapping_passes(logs: Sequence[Path], config: DoorbatchConfig, with_colors: bool = False
                   ) -> tuple[list[Path], list[Recording], str | None]:
    """The logs as the passes ``doorbatch map`` builds from: read as passes of one robot (:func:`load_passes`),
    put in the order of their first scans (on the recorder's clock) where they happened one after another or only
    that order chains
    (:func:`time_order`; the logs in that order and a note saying so), and cut by ``mapping.pass_duration_s``
    (:func:`~doorbatch.pipeline.time_passes.split_into_passes`)."""
    paths = [Path(p) for p in logs]
    recordings = load_passes(paths, config, with_colors)
    order = time_order(recordings, config)
    note = None
    if order is not None:
        paths, recordings = [paths[i] for i in order], [recordings[i] for i in order]
        note = ("the passes were not given in the order of their first scans' times: mapped in that order "
                f"({', '.join(p.name for p in paths)}), the order they happened in (the grid stage classifies each "
                "pass against the passes before it)")
    return paths, split_into_passes(recordings, config.mapping.pass_duration_s), note


def moved_odometry(rec: Recording, motion: npt.ArrayLike) -> Recording:
    """``rec`` with its odometry moved by the rigid ``motion`` T (x, y, yaw): o ↦ T ⊕ o; a reference that repeats
    the odometry (r = M ⊕ o) then repeats the moved one by M ⊕ T⁻¹. A pass without odometry (a piece of a log
    matched at constant velocity) has nothing to move."""
    if rec.odometry is None:
        return rec
    t = np.asarray(motion, dtype=np.float64).reshape(3)
    poses = compose(np.broadcast_to(t, rec.odometry.poses.shape), rec.odometry.poses)
    repeat = None if rec.odometry_to_reference is None else compose(rec.odometry_to_reference, inverse(t))
    return replace(rec, odometry=replace(rec.odometry, poses=poses), odometry_to_reference=repeat,
                   logged_odometry=rec.drawn_odometry)  # the log's tree stays where it was


def carried_bridges(recordings: Sequence[Recording], config: DoorbatchConfig) -> tuple[list[Recording], list[str]]:
    """The passes with each odometry jump bridged in one pass (a restart, a set pose) carried on to the passes after it
    that continue the jump's new frame: a pass whose odometry starts where the previous one's *raw* odometry ended
    (its bridged end moved back by its bridge B⁻¹) is moved by B (:func:`moved_odometry`), so that it continues the
    bridged one; and a note per pass moved. (A restart bridged in pass 2 left pass 3, recorded on after it, 10.9 m
    from where pass 2 ended: "disjoint coordinate frames".)"""
    out = list(recordings[:1])
    notes: list[str] = []
    carried: FloatArray | None = None  # the motion the previous recording was moved by
    for nxt in recordings[1:]:
        prev = out[-1]
        if nxt.continues_piece(prev):  # a later piece of a moved log moves with it
            if carried is not None:
                nxt = replace(moved_odometry(nxt, carried), odometry_bridge=None if nxt.odometry_bridge is None
                              else compose(carried, nxt.odometry_bridge))
            out.append(nxt)
            continue
        carried = None
        bridge = prev.odometry_bridge
        if bridge is not None and nxt.odometry is not None and prev.odometry is not None and not continues(
                prev, nxt, config):
            raw_end = compose(inverse(bridge), prev.odometry.poses[-1])  # where the driver's own odometry ended
            if within_continuity(pose_gap(raw_end, nxt.odometry.poses[0]), config):
                own = np.zeros(3) if nxt.odometry_bridge is None else nxt.odometry_bridge
                nxt = replace(moved_odometry(nxt, bridge), odometry_bridge=compose(bridge, own))
                carried = bridge
                notes.append(f"{nxt.path}: its odometry continues the frame {Path(prev.path).name}'s odometry "
                             "jumped to: moved as that jump was bridged")
        out.append(nxt)
    return out, notes


def check_common_frame(recordings: Sequence[Recording], source: str, config: DoorbatchConfig) -> None:
    """Passes must share one map frame.

    Raises:
        PipelineError: reference poses in different frames, or odometry that jumps between passes.
    """
    if len(recordings) < 2:
        return
    if source == "reference":
        frames = {r.reference.frame_id for r in recordings if r.reference is not None}
        if len(frames) > 1:
            raise PipelineError(f"passes have disjoint coordinate frames: reference poses in {sorted(frames)}")
        return
    for prev, nxt in itertools.pairwise(recordings):
        if continues(prev, nxt, config):
            continue
        if prev.odometry is None or nxt.odometry is None:
            raise PipelineError(f"{nxt.path}: passes have disjoint coordinate frames: without a reference, "
                                "several passes need one continuous odometry frame")
        jump_m, jump_deg = odometry_jump(prev, nxt)
        have = all(r.reference is not None and not r.reference_is_odometry for r in recordings)
        reference = ("the logs have a reference pose topic: --pose-source reference (what is chosen when none is "
                     "given) uses it" if have else "give a reference pose topic")
        raise PipelineError(
            f"{nxt.path}: passes have disjoint coordinate frames: its odometry starts {jump_m:.2f} m and "
            f"{jump_deg:.1f}° from where {Path(prev.path).name} ended (mapping.odometry_continuity_m = "
            f"{config.mapping.odometry_continuity_m}, _deg = {config.mapping.odometry_continuity_deg}); {reference}, "
            "map the logs separately, or "
            "try --set mapping.join_passes=true (each pass placed on the map of the ones before it by global "
            "localization)")


def _chain_scanmatch(recordings: Sequence[Recording], config: DoorbatchConfig) -> tuple[list[PassPoses], list[str]]:
    """Scan matching over all passes as one sequence (one odometry frame, the submap carries over); without
    odometry (one pass: :func:`check_common_frame`) each scan is predicted at constant velocity. Returns the
    passes and warnings."""
    per_pass = [pass_poses(rec, "odometry", config) for rec in recordings]
    idx = [np.flatnonzero(p.valid) for p in per_pass]
    scans = [rec.scans.hits_base(int(i)) for rec, ii in zip(recordings, idx, strict=True) for i in ii]
    odom = np.concatenate([p.poses[ii] for p, ii in zip(per_pass, idx, strict=True)])
    no_odometry = any(rec.odometry is None for rec in recordings)
    stamps = np.concatenate([p.stamps_ns[ii] for p, ii in zip(per_pass, idx, strict=True)])
    result = scan_match_trajectory(scans, None if no_odometry else odom, config.scanmatch, stamps)
    matched = result.poses
    warnings = []
    if no_odometry:
        share = float(np.mean(result.degenerate)) if result.degenerate.size else 0.0
        warnings.append(f"no odometry: poses from scan matching alone, each scan predicted at constant velocity; "
                        f"{share:.0%} of the scans left a direction unobserved (a featureless corridor), along which "
                        "the trajectory is that guess")
    out, start = [], 0
    for p, ii in zip(per_pass, idx, strict=True):
        poses = p.poses.copy()
        poses[ii] = matched[start: start + ii.shape[0]]
        start += ii.shape[0]
        out.append(PassPoses(p.log, p.stamps_ns, poses, p.valid, "scanmatch"))
    return out, warnings


def in_reference_frame(passes: list[PassPoses], recordings: Sequence[Recording]
                       ) -> tuple[list[PassPoses], str | None]:
    """Scan-matched passes (in the passes' common odometry frame) moved into the reference frame of the first pass
    whose reference is its odometry moved rigidly (``Recording.odometry_to_reference``: a raw CARMEN log, or a
    simulator's perfect odometry beside its ground truth), so that the map lies where the reference says, as with
    ``--pose-source reference``, whatever the order of the passes; and a note. That motion T takes the odometry's
    poses onto the reference's (the identity for a raw CARMEN log). Passes unchanged where no pass has one."""
    first = next((r for r in recordings if r.odometry_to_reference is not None), None)
    if first is None or first.odometry_to_reference is None:
        return passes, None
    motion = first.odometry_to_reference
    if float(np.hypot(motion[0], motion[1])) < 1e-9 and abs(float(motion[2])) < 1e-12:
        return passes, None
    moved = [replace(p, poses=compose(np.broadcast_to(motion, p.poses.shape), p.poses)) for p in passes]
    return moved, (f"{first.path}: the reference is the odometry moved rigidly by ({motion[0]:.3f} m, "
                   f"{motion[1]:.3f} m, {math.degrees(float(motion[2])):.2f}°): the scan-matched poses are moved "
                   "with it into the reference's frame")


def map_scans(rec: Recording, poses: PassPoses, stride: int, dropout_max_beams: int) -> Iterator[MapScan]:
    """Every ``stride``-th scan of a pass with a valid pose, in the map frame (the grid stage's input); no-return
    beams that are dropouts (:func:`~doorbatch.geometry.laser.dropouts`, ``grid.dropout_max_beams``) clear
    nothing."""
    scans = rec.scans
    for i in range(0, len(scans), stride):
        if not poses.valid[i]:
            continue
        pose = poses.poses[i]
        rot = rotation_matrix(pose[2])
        affine = scans.laser_to_base[i]
        origin = rot @ affine[:, 2] + pose[:2]
        pts, hit = scans.endpoints_base(i)
        r = scans.ranges[i]
        with np.errstate(invalid="ignore"):
            no_return = np.isposinf(r) | (np.isfinite(r) & (r >= scans.range_max[i]))
        no_return &= ~dropouts(no_return, hit, dropout_max_beams, wraps_around(scans.angle_increment[i], r.shape[0]))
        angles = scans.angle_min[i] + scans.angle_increment[i] * np.flatnonzero(no_return)
        dirs = np.stack([np.cos(angles), np.sin(angles)], axis=1) @ (rot @ affine[:, :2]).T
        yield MapScan(origin, pts[hit] @ rot.T + pose[:2], dirs, float(scans.range_max[i]))


def integrate_pass(mapper: GridMapper, rec: Recording, poses: PassPoses, stride: int, dropout_max_beams: int,
                   bar: Progress | None = None) -> None:
    """Add every valid scan of one pass to the mapper (map frame), then close the pass (``bar``: advanced per
    scan added)."""
    for scan in map_scans(rec, poses, stride, dropout_max_beams):
        mapper.add_scan(*scan)
        if bar is not None:
            bar.update()
    mapper.end_pass()


def grid_of(recordings: Sequence[Recording], passes: Sequence[PassPoses], config: DoorbatchConfig,
            progress: Callable[[int], object] | None = None) -> GridMapResult:
    """The grid stage over passes at their poses, one after the other (``progress``: called once per pass)."""
    mapper = GridMapper(config.grid, config.doors)
    with progress_bar(None, "map: grid", unit="scan") as bar:  # a long log's pass takes minutes
        bar.set_total(sum(int(np.count_nonzero(p.valid[::config.mapping.scan_stride])) for p in passes))
        for rec, poses in zip(recordings, passes, strict=True):
            integrate_pass(mapper, rec, poses, config.mapping.scan_stride, config.grid.dropout_max_beams, bar)
            if progress is not None:
                progress(1)
    return mapper.finish()


@dataclass(frozen=True)
class PartialMap:
    """What :func:`static_map_of` makes of passes in one frame: the static map, and the map pose and odometry pose
    of the last scan with a pose (where the next pass's poses continue from)."""

    occupancy: OccupancyMap
    end_pose: FloatArray
    end_odometry: FloatArray


def static_map_of(recordings: Sequence[Recording], source: str, config: DoorbatchConfig) -> PartialMap:
    """The static grid map of passes in one frame from odometry or scan matching (``source``), without the em
    stage: what :func:`build_map` makes of them (door detection included), for localizing another pass on it."""
    passes = (_chain_scanmatch(recordings, config)[0] if source == "scanmatch"
              else [pass_poses(rec, source, config) for rec in recordings])
    occupancy = grid_of(recordings, passes, config).static_map
    odometry = pass_poses(recordings[-1], "odometry", config)
    both = np.flatnonzero(passes[-1].valid & odometry.valid)
    if both.size == 0:
        raise PipelineError(f"{recordings[-1].path}: no scan has a {source} pose: nothing to place the next pass on")
    return PartialMap(occupancy, passes[-1].poses[both[-1]], odometry.poses[both[-1]])


def build_map(logs: Sequence[Path | str] | Path | str, config: DoorbatchConfig | Mapping[str, Any] | None = None,
              progress: Callable[[int], object] | None = None,
              recordings: Sequence[Recording] | None = None) -> DoorMap:
    """Door-augmented occupancy grid from logs, each one pass (doors stationary within a pass; or cut into passes
    of ``mapping.pass_duration_s``: :mod:`~doorbatch.pipeline.time_passes`);
    ``recordings``: the logs already loaded (the em stage loads them with colours).

    ``config``: as :func:`~doorbatch.config.config_of` takes it (None: the defaults).

    Raises:
        PipelineError: no usable pose source, or passes in disjoint coordinate frames.
        InputDataError: a log cannot be read or has no scans.
        UsageError: no log given; ConfigError: a config mapping with an unknown key or a wrong value.
    """
    config = config_of(config)
    paths = [Path(logs)] if isinstance(logs, str | Path) else [Path(p) for p in logs]
    if not paths and not recordings:
        raise UsageError("build_map: no log given")
    seconds: dict[str, float] = {}
    t0 = time.perf_counter()
    ordered = None
    if recordings is None:
        _, recordings, ordered = mapping_passes(paths, config)
    seconds["read"] = time.perf_counter() - t0
    for rec in recordings:
        log.info("%s: %d scans, odometry %s, reference %s", rec.path, len(rec.scans),
                 "yes" if rec.odometry is not None else "no", "yes" if rec.reference is not None else "no")
    source, warnings = choose_pose_source(recordings, config.mapping.pose_source, config)
    warnings = [ordered, *warnings] if ordered else warnings
    if source == "reference":
        warnings += reference_jitter_notes(recordings, config)
    log.info("pose source: %s", source)
    if source != "reference" and len(recordings) > 1:
        recordings, carried = carried_bridges(recordings, config)
        warnings += carried
    if source != "reference" and config.mapping.join_passes and len(recordings) > 1:
        from doorbatch.pipeline.join_passes import join_passes  # it localizes, and localization reads pass poses

        # one frame for all passes, or an error
        recordings, joined = join_passes(recordings, lambda passes: static_map_of(passes, source, config), config)
        warnings += joined
    else:
        check_common_frame(recordings, source, config)
    t0 = time.perf_counter()
    if source == "scanmatch":
        passes, matching_notes = _chain_scanmatch(recordings, config)
        passes, moved = in_reference_frame(passes, recordings)
        warnings += matching_notes + ([moved] if moved else [])
    else:
        passes = [pass_poses(rec, source, config) for rec in recordings]
    seconds["poses"] = time.perf_counter() - t0
    if not any(p.valid.any() for p in passes):
        article = "an" if source[0] in "aeiou" else "a"
        raise PipelineError(f"no scan has {article} {source} pose within mapping.max_pose_gap_s "
                            f"({config.mapping.max_pose_gap_s} s) of one: nothing to map (try another --pose-source)")
    warnings += [w for rec in recordings for w in rec.warnings]
    if len(recordings) == 1:
        warnings.append(f"{recordings[0].path}: one pass: doors are found where passes see their leaves at different "
                        "angles (paper 000), so one pass finds few or none, and a leaf that swung in view stays in "
                        "map.pgm; give several passes, or cut a long log into passes with --set "
                        "mapping.pass_duration_s=SECONDS")
    for p in passes:
        skipped = int((~p.valid).sum())
        if skipped:
            warnings.append(f"{p.log}: {skipped} of {p.valid.shape[0]} scans have no {source} pose and are skipped")
    t0 = time.perf_counter()
    result = grid_of(recordings, passes, config, progress)
    seconds["grid"] = time.perf_counter() - t0
    warnings += disagreement_notes(recordings, passes, result.static_map, source, config)
    warnings += mount_notes(recordings, passes, source, config)
    return DoorMap(result.static_map, result.doors, passes, source, result.n_dynamic_points, warnings, seconds,
                   result.grid)


# The disagreement check reads every this-many-th mapped scan: a share needs thousands of end points, not all of them
# (every scan cost a third of the grid stage's time on a 40 Hz Hokuyo log).
_SHARE_SCAN_STRIDE = 10


def free_end_point_share(rec: Recording, poses: PassPoses, free: FreeCells, config: DoorbatchConfig) -> float:
    """The share of a pass's scan end points (placed at its poses; every ``_SHARE_SCAN_STRIDE``-th mapped scan) that
    fall in ``free`` cells (the map grows to hold every end point, so none falls outside it)."""
    total = hits = 0
    stride = config.mapping.scan_stride * _SHARE_SCAN_STRIDE
    for scan in map_scans(rec, poses, stride, config.grid.dropout_max_beams):
        held = free.holds(scan.points)
        total += held.shape[0]
        hits += int(held.sum())
    return hits / total if total else 0.0


def disagreement_notes(recordings: Sequence[Recording], passes: Sequence[PassPoses], occupancy: OccupancyMap,
                       source: str, config: DoorbatchConfig) -> list[str]:
    """A warning naming the passes whose end points fall in the map's free cells more often than
    ``mapping.pass_disagreement_warn_share`` (their poses disagree with the map the passes made together)."""
    free = free_cells(occupancy, config.localize.map_free_at_most)
    shares = [free_end_point_share(rec, p, free, config) for rec, p in zip(recordings, passes, strict=True)]
    bad = [(rec.path, share) for rec, share in zip(recordings, shares, strict=True)
           if share > config.mapping.pass_disagreement_warn_share]
    if not bad:
        return []
    listed = "; ".join(f"{share:.0%} of {path}'s" for path, share in bad)
    hint = " (try --pose-source scanmatch)" if source != "scanmatch" else ""
    return [f"the {source} poses disagree with the map: {listed} scan end points fall in cells the map holds free "
            f"(people and doors take a few, up to a quarter in a crowd): walls are smeared and doors found may be "
            f"false{hint}"]


def mount_notes(recordings: Sequence[Recording], passes: Sequence[PassPoses], source: str, config: DoorbatchConfig
                ) -> list[str]:
    """A warning when the scans say the laser's mount yaw differs from the TF's: the median angle between matched and
    reference motion of straight scan pairs (:func:`~doorbatch.pipeline.poses.mount_check.mount_yaw_offsets`) over
    ``mapping.mount_yaw_warn_deg`` and three standard errors. Reference poses only: scan-matched ones agree with the
    scans by construction."""
    m = config.mapping
    if source != "reference" or m.mount_check_pairs == 0:
        return []
    offsets = np.concatenate([mount_yaw_offsets(rec, p.poses, p.valid, m.mount_check_step_m,
                                                math.radians(m.mount_check_max_turn_deg), m.mount_check_pairs)
                              for rec, p in zip(recordings, passes, strict=True)])
    if offsets.size < m.mount_check_min_pairs:
        return []
    median = float(np.median(offsets))
    q75, q25 = np.percentile(offsets, [75, 25])
    standard_error = float(q75 - q25) / 1.349 / math.sqrt(offsets.size)
    if abs(median) < math.radians(m.mount_yaw_warn_deg) or abs(median) < 3.0 * standard_error:
        return []
    turned, moved = math.degrees(-median), math.degrees(median)
    return [f"the laser's mount yaw in the TF disagrees with the scans by about {turned:+.1f}° (the laser turned that "
            f"way against base_link): matched scan pairs moved at {moved:+.1f}° to the reference's motion (median of "
            f"{offsets.size} straight pairs). Walls seen from opposite directions stand apart in the map and doors "
            "found may be false; check the base_link → laser transform (--set io.laser_mount=[x,y,z,roll,pitch,yaw] "
            "--set io.laser_mount_replaces_tf=true gives another)"]


def without_leaves(door_map: DoorMap, doors: Sequence[PreviewDoor], config: DoorbatchConfig) -> DoorMap:
    """The door map whose static map also lacks the leaves of ``doors`` (the map directory's), taken out as the
    grid stage takes out its own (:func:`~doorbatch.pipeline.gridmap.doors.remove_leaves`: the sector each
    leaf swept over its opening range, the hinge kept).

    Paper 000's static map holds no leaves: the localizer models them from the door states. A door only the
    em stage found (one that never moved while mapping) would otherwise stay in the grid at the angle it
    stood at, e.g. a leaf standing open into the corridor where a later log has it closed.
    """
    if door_map.grid is None or not doors:
        return door_map
    grid = copy.deepcopy(door_map.grid)
    remove_leaves(grid, [DetectedDoor(d.hinge_x, d.hinge_y, d.length, d.closed_yaw, d.angle_min, d.angle_max, 0,
                                      d.moved) for d in doors], config.doors, config.grid)
    return replace(door_map, static_map=to_occupancy_map(grid), grid=grid)
