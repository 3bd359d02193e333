"""What ``ros2 bag info`` shows, plus what doorbatch makes of a log: roles, and problems found.

One streaming pass over every message: counts and rates per topic, header stamps going backwards,
gaps, scans whose ranges disagree with their angles, the transform tree (is the laser frame connected to
base_link? is there odom→base_link?). Problems carry a severity: an ``error`` makes the log unusable for
doorbatch's stages, a ``warning`` is worth knowing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import LogContentError
from doorbatch.geometry.laser import beam_runs, wraps_around
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.io.decode import ODOMETRY, decode_scan, decode_transforms, stamp_to_ns
from doorbatch.io.log_clock import LogClock, long_gaps
from doorbatch.io.map_topic import OCCUPANCY_GRID
from doorbatch.io.pose_topic import POSE_TYPES
from doorbatch.io.reader import most_are_bad, open_log
from doorbatch.io.recording import (
    buffered_transforms,
    clock_fault,
    clock_lags_s,
    lost_times_note,
    missing_laser_tf_hint,
    no_sweep_note,
    odometry_frame,
    odometry_frame_note,
    resolve_base_frame,
    tf_odometry,
    tf_reference,
    unset_stamps,
)
from doorbatch.io.roles import TopicInfo
from doorbatch.records import Role, Scan, Transform


class Severity(StrEnum):
    """How bad a problem is."""

    ERROR = "error"
    WARNING = "warning"


@dataclass(frozen=True)
class Problem:
    """One finding: severity, topic (or None) and what is wrong."""

    severity: Severity
    topic: str | None
    message: str


def _unused_hint(info: TopicInfo) -> str | None:
    """What an unused topic can still be given as: a map (``--map LOG``), odometry or a reference (an Odometry
    topic: ``topics.odometry``, ``topics.reference``) or a start pose (``--init TOPIC``)."""
    if info.msgtype == OCCUPANCY_GRID:
        return "a map: localize --map LOG"
    if info.msgtype == ODOMETRY:  # an EKF's /odometry/filtered: poses in the odom frame, no start in the map's
        return f"odometry or a reference: --set topics.odometry={info.name} (or topics.reference)"
    if info.msgtype in POSE_TYPES:
        return f"a start pose: localize --init {info.name}"
    return None


def _read_as(info: TopicInfo, why: str | None) -> str | None:
    """``why`` with, for a topic of a Foxglove schema, the ROS type its messages are read as."""
    if not info.schema:
        return why
    note = f"{info.schema} read as {info.msgtype}"
    return f"{why}; {note}" if why else note


@dataclass
class TopicReport:
    """Per-topic statistics."""

    name: str
    msgtype: str
    count: int
    rate_hz: float
    role: str | None
    why: str | None


@dataclass
class LogReport:
    """The result of :func:`inspect_log`."""

    path: str
    storage: str
    size_bytes: int
    start_ns: int
    end_ns: int
    duration_s: float
    message_count: int
    topics: list[TopicReport]
    frames: list[str]
    problems: list[Problem] = field(default_factory=list)
    odometry: str = "none"  # where the odometry comes from: an Odometry topic, or TF odom → base
    reference: str = "none"  # where the reference comes from: a pose topic, or TF map → base (a localizer's)
    # The clock doorbatch times the scans by: their header stamps, and how those relate to the recorder's clock
    # (Duration, Start, End and the rates are by log time).
    clock: str = "scan header stamps, on the recorder's clock"
    # The laser read: beams, field of view, range limits, and the share of beams that return.
    laser: str = "none"

    @property
    def errors(self) -> list[Problem]:
        """The problems that make the log unusable."""
        return [p for p in self.problems if p.severity is Severity.ERROR]

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``--json``."""
        data = asdict(self)
        data["problems"] = [{**asdict(p), "severity": p.severity.value} for p in self.problems]
        return data


@dataclass
class _TopicStats:
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    last_stamp_ns: int | None = None
    backwards: int = 0
    first_backwards: str = ""
    periods: list[int] = field(default_factory=list)
    header_stamps: list[int] = field(default_factory=list)  # every header stamp, for recording.unset_stamps
    stamps: list[int] = field(default_factory=list)  # header stamps and log times of scan and odometry topics
    log_times: list[int] = field(default_factory=list)


def _size(path: Path) -> int:
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return path.stat().st_size


def _header_stamp(msg: Any) -> int | None:
    header = getattr(msg, "header", None)
    return stamp_to_ns(header.stamp) if header is not None else None


def inspect_log(path: Path, config: DoorbatchConfig | None = None,
                progress: Callable[[int], object] | None = None) -> LogReport:
    """Read a whole log once and report topics, roles and problems.

    Raises:
        LogReadError: the file is not a readable log (empty, truncated, unknown format).
    """
    config = config or DoorbatchConfig()
    path = Path(path)
    problems: list[Problem] = []
    stats: dict[str, _TopicStats] = {}
    transforms: list[Transform] = []  # buffered as load_recording buffers them, after the pass
    scan_frames: set[str] = set()
    with open_log(path, config) as reader:
        roles = reader.roles
        role_of = roles.role_of()
        scan_topic = roles.topic(Role.SCAN)
        bad_scans: list[str] = []  # reasons, one per scan that cannot be decoded
        first_scan: Scan | None = None
        beams_seen = beams_hit = 0
        near = _NearBeams(config.io.self_hit_max_range_m)
        for raw in reader.raw_messages():
            st = stats.setdefault(raw.topic, _TopicStats())
            st.count += 1
            if st.last_ns is not None:
                st.periods.append(raw.log_time_ns - st.last_ns)
            st.first_ns = raw.log_time_ns if st.first_ns is None else st.first_ns
            st.last_ns = raw.log_time_ns
            if role_of.get(raw.topic) is Role.TRANSFORMS:
                transforms.extend(decode_transforms(raw.msg, raw.topic.rstrip("/").endswith("tf_static"),
                                                    raw.log_time_ns))
                continue
            stamp = _header_stamp(raw.msg)
            if stamp is not None:
                st.header_stamps.append(stamp)
            if stamp is not None and role_of.get(raw.topic) in (Role.SCAN, Role.ODOMETRY):
                st.stamps.append(stamp)
                st.log_times.append(raw.log_time_ns)
            if stamp is not None:
                if st.last_stamp_ns is not None and stamp < st.last_stamp_ns:
                    st.backwards += 1
                    if st.backwards == 1:
                        st.first_backwards = (f"header stamp {stamp / 1e9:.6f} s after "
                                              f"{st.last_stamp_ns / 1e9:.6f} s (message {st.count})")
                st.last_stamp_ns = stamp
            if raw.topic == scan_topic:
                try:
                    scan = decode_scan(raw.msg, raw.log_time_ns, raw.topic, raw.msgtype)
                except LogContentError as err:
                    bad_scans.append(err.reason)
                else:
                    scan_frames.add(scan.frame_id)
                    first_scan = first_scan or scan
                    r = scan.ranges
                    beams_seen += r.shape[0]
                    beams_hit += int(np.count_nonzero((r >= scan.range_min) & (r < scan.range_max)))
                    near.add(scan)
            if progress is not None:
                progress(1)
        if bad_scans and scan_topic is not None:  # as LogReader.messages: skipped unless most are bad
            n_scans = stats[scan_topic].count
            most = most_are_bad(len(bad_scans), n_scans)
            problems.append(Problem(Severity.ERROR if most else Severity.WARNING, scan_topic,
                                    bad_scans[0] if most else f"{len(bad_scans)} of {n_scans} scans are unusable and "
                                                              f"skipped (first: {bad_scans[0]})"))
        tf, tf_note = buffered_transforms(transforms, reader.scan_origin_mounts().values(), config)
        problems.extend(Problem(Severity.WARNING, None, w) for w in [*reader.warnings, *([tf_note] if tf_note else [])])
        topics = [
            TopicReport(info.name, info.schema or info.msgtype,  # a topic not read (no definition): the index's count
                        stats[info.name].count if info.name in stats else info.count,
                        _rate(stats.get(info.name)), role_of[info.name].value if info.name in role_of else None,
                        _read_as(info, roles.reasons.get(info.name) if info.name in role_of else _unused_hint(info)))
            for info in sorted(reader.topics.values(), key=lambda t: t.name)
        ]
        report = LogReport(
            path=str(path), storage=reader.storage, size_bytes=_size(path),
            start_ns=min((s.first_ns for s in stats.values() if s.first_ns is not None), default=0),
            end_ns=max((s.last_ns for s in stats.values() if s.last_ns is not None), default=0),
            duration_s=0.0, message_count=sum(s.count for s in stats.values()), topics=topics,
            frames=sorted(tf.frames | scan_frames), problems=problems,
        )
    report.duration_s = (report.end_ns - report.start_ns) / 1e9
    if first_scan is not None and scan_topic is not None:
        _describe_laser(report, scan_topic, first_scan, beams_hit / max(beams_seen, 1), config.io.narrow_fov_warn_deg)
        _describe_sweep(report, scan_topic, first_scan.sweep_s, _rate(stats.get(scan_topic)), config.io.deskew)
        _describe_self_hits(report, scan_topic, first_scan, near, config.io.self_hit_min_share)
    _check_roles(report, roles.topics, scan_frames, tf, config, stats)
    _check_stamps(report, stats, role_of, config.io.gap_factor)
    _check_clocks(report, stats, role_of, tf, config)
    return report


def _describe_laser(report: LogReport, topic: str, scan: Scan, returned: float, narrow_deg: float) -> None:
    """The laser line of a report, and a warning for a field of view under ``narrow_deg``."""
    n = scan.ranges.shape[0]
    fov_deg = math.degrees(abs(scan.angle_increment) * n)
    ends = sorted(math.degrees(scan.angle_min + k * scan.angle_increment) for k in (0, n - 1))
    report.laser = (f"{topic}: {n} beams over {fov_deg:.1f}° ({ends[0]:.1f}° to {ends[1]:.1f}°), "
                    f"{scan.range_min:g} to {scan.range_max:g} m, {returned:.0%} of beams return")
    if fov_deg < narrow_deg:
        report.problems.append(Problem(
            Severity.WARNING, topic,
            f"a field of view of {fov_deg:.0f}° (a depth camera's?): door leaves are seen in part and briefly, so "
            "doors can be missed, scan matching falls back to odometry more often, and global localization has "
            "little to go on; tracking from a known start works (docs/results.md, round four)"))


@dataclass
class _NearBeams:
    """Per beam index, how many scans return nearer than ``max_range_m`` (at or beyond their range_min), over
    the scans with the first scan's beam count."""

    max_range_m: float
    counts: npt.NDArray[np.int64] | None = None
    scans: int = 0

    def add(self, scan: Scan) -> None:
        r = scan.ranges
        if self.counts is None:
            self.counts = np.zeros(r.shape[0], np.int64)
        if r.shape[0] != self.counts.shape[0]:
            return
        self.counts += (r >= scan.range_min) & (r < self.max_range_m)
        self.scans += 1


def _describe_self_hits(report: LogReport, topic: str, scan: Scan, near: _NearBeams, min_share: float) -> None:
    """A warning for beams that return within ``near.max_range_m`` in at least ``min_share`` of the scans: the
    robot's own body in the laser's view, no surface of any map. Localization weighs them against the map's walls
    (a bias towards poses near a wall) unless ``localize.laser_min_range`` leaves them out."""
    if near.counts is None or near.scans < 10:  # too few scans to tell a body from a wall passed by
        return
    starts, stops = beam_runs(near.counts >= min_share * near.scans)
    if not starts.size:
        return
    runs = list(zip(starts.tolist(), (stops - 1).tolist(), strict=True))
    n = near.counts.shape[0]
    if len(runs) > 1 and runs[0][0] == 0 and runs[-1][1] == n - 1 and wraps_around(scan.angle_increment, n):
        runs = [(runs[-1][0], runs[0][1]), *runs[1:-1]]  # one run across the first beam of a full turn
    n_near = sum((b - a) % n + 1 for a, b in runs)
    where = ", ".join(
        f"{a}–{b} ({math.degrees(scan.angle_min + a * scan.angle_increment):.0f}° to "
        f"{math.degrees(scan.angle_min + b * scan.angle_increment):.0f}°)" if b != a else
        f"{a} ({math.degrees(scan.angle_min + a * scan.angle_increment):.0f}°)" for a, b in runs)
    report.problems.append(Problem(
        Severity.WARNING, topic,
        f"beams {where}, {n_near} of {near.counts.shape[0]}, return within {near.max_range_m:g} m in at least "
        f"{min_share:.0%} of the scans: the robot's own body (posts, a bumper)? They are no surface of the map; "
        f"--set localize.laser_min_range={near.max_range_m:g} leaves them out of localization"))


def _describe_sweep(report: LogReport, topic: str, sweep_s: float, rate_hz: float, deskew: bool) -> None:
    """The laser line's sweep (time_increment), whether the scans are deskewed, and a warning when the
    sweep is longer than the scan period (a driver that wrote something else there: not deskewed)."""
    if sweep_s <= 0.0:
        return
    if no_sweep := no_sweep_note(sweep_s, 1.0 / rate_hz if rate_hz > 0 else math.inf):
        report.laser += f", time_increment × beams {1e3 * sweep_s:.0f} ms"
        report.problems.append(Problem(Severity.WARNING, topic, no_sweep))
        return
    report.laser += f", sweeps {1e3 * sweep_s:.0f} ms ({'deskewed with the odometry' if deskew else 'io.deskew off'})"


def _rate(st: _TopicStats | None) -> float:
    if st is None or st.count < 2 or st.first_ns is None or st.last_ns is None or st.last_ns == st.first_ns:
        return 0.0
    return (st.count - 1) / ((st.last_ns - st.first_ns) / 1e9)


def _check_roles(report: LogReport, chosen: dict[Role, tuple[str, ...]], scan_frames: set[str], tf: TfBuffer,
                 config: DoorbatchConfig, stats: dict[str, _TopicStats]) -> None:
    frames, base_note = resolve_base_frame(tf, config.frames)
    add = report.problems.append
    if base_note:
        add(Problem(Severity.WARNING, None, base_note))
    scan = chosen.get(Role.SCAN)
    if not scan:
        add(Problem(Severity.ERROR, None, "no sensor_msgs/LaserScan topic: doorbatch needs a 2D laser scan"))
    elif stats.get(scan[0], _TopicStats()).count == 0:
        add(Problem(Severity.ERROR, scan[0], "scan topic has no messages"))
    if Role.REFERENCE in chosen:
        name = chosen[Role.REFERENCE][0]
        kind = next((t.msgtype for t in report.topics if t.name == name), "")
        report.reference = f"{name} ({kind.replace('/msg/', '/')})" if kind else name
    elif tf_reference(tf, frames)[0]:
        report.reference = f"TF {frames.map}→{frames.base_link} (a localizer's or SLAM's moving map→odom)"
    if Role.ODOMETRY in chosen:
        report.odometry = f"{chosen[Role.ODOMETRY][0]} (nav_msgs/Odometry)"
    else:
        odom_frame = odometry_frame(tf, frames.odom, frames.base_link)
        if odom_frame is not None:
            report.odometry = f"TF {odom_frame}→{frames.base_link}"
        if odom_frame is None:
            add(Problem(Severity.WARNING, None,
                        f"no odometry: no nav_msgs/Odometry topic and no TF {frames.odom}→{frames.base_link}"))
        elif odom_frame != frames.odom:
            add(Problem(Severity.WARNING, None, odometry_frame_note(odom_frame, frames.odom, frames.base_link)))
    assume = config.io.assume_identity_laser_tf
    mount = config.io.laser_mount
    for frame in sorted(scan_frames):
        if frame != frames.base_link and not tf.can_transform(frames.base_link, frame):
            message = f"no transform from the laser frame {frame!r} to {frames.base_link!r}"
            if mount is not None:
                add(Problem(Severity.WARNING, scan[0] if scan else None, f"{message}; io.laser_mount {list(mount)}"))
            elif assume:
                add(Problem(Severity.WARNING, scan[0] if scan else None, message + "; assuming identity"))
            else:
                add(Problem(Severity.ERROR, scan[0] if scan else None,
                            f"{message} ({missing_laser_tf_hint(tf, frames.base_link, frame)})"))


def _check_stamps(report: LogReport, stats: dict[str, _TopicStats], role_of: dict[str, Role],
                  gap_factor: float) -> None:
    for name, st in sorted(stats.items()):
        role = role_of.get(name)
        if st.backwards:
            sorted_note = "; map and localize sort them by stamp" if role in (Role.SCAN, Role.ODOMETRY,
                                                                             Role.REFERENCE) else ""
            report.problems.append(Problem(Severity.WARNING, name, f"stamps go backwards {st.backwards} time(s): "
                                                                   f"first {st.first_backwards}{sorted_note}"))
        unset_at = unset_stamps(st.header_stamps)
        if role is Role.SCAN and len(st.log_times) == len(st.header_stamps):
            lost = lost_times_note(np.where(unset_at, st.log_times, st.header_stamps).tolist())
            report.problems.extend([Problem(Severity.ERROR, name, lost)] if lost else [])
        unset = int(unset_at.sum())
        if unset:
            report.problems.append(Problem(Severity.WARNING, name, f"{unset} of {st.count} header stamps "
                                                                   f"are 0 (unset): their log time stands in"))
        periods = np.asarray(st.periods, dtype=np.float64)
        gaps = periods[long_gaps(periods, gap_factor)]
        if gaps.size:
            report.problems.append(Problem(
                Severity.WARNING, name,
                f"{gaps.size} gap(s) in time longer than {gap_factor:g}× the {np.median(periods) / 1e9:.3f} s period "
                f"(longest {gaps.max() / 1e9:.3f} s)"))


def clock_line(stamps_ns: npt.NDArray[np.int64], log_ns: npt.NDArray[np.int64], mismatch_s: float) -> str:
    """What clock the scans' header stamps are on: the recorder's (one clock for :meth:`LogClock.of_pairs`), or
    another (a simulator's sim time recorded on wall-clock time), with where the stamps start and how fast they
    run against the recording. Unset stamps (0) are left out: where every one is unset, the log times stand in."""
    unset = unset_stamps(stamps_ns.tolist())
    if unset.all():
        return "log times: every scan header stamp is unset (Problems)"
    stamps_ns, log_ns = stamps_ns[~unset], log_ns[~unset]
    if not LogClock.of_pairs(log_ns, stamps_ns, mismatch_s).offset_ns:
        return "scan header stamps, on the recorder's clock"
    span_log = float(log_ns[-1] - log_ns[0])
    rate = f", advancing {float(stamps_ns[-1] - stamps_ns[0]) / span_log:.2f} s per recorded second" if span_log > 0 \
        else ""
    return (f"scan header stamps, on another clock than the recorder's (sim time?): from {stamps_ns[0] / 1e9:.3f} s"
            f"{rate}; Duration, Start, End and the rates above are the recorder's")


def _check_clocks(report: LogReport, stats: dict[str, _TopicStats], role_of: dict[str, Role], tf: TfBuffer,
                  config: DoorbatchConfig) -> None:
    """Scan and odometry header stamps on two clocks (:func:`doorbatch.io.recording.on_one_clock`); without an
    odometry topic, the odometry from TF."""
    of = {role_of.get(name): st for name, st in stats.items() if st.stamps}
    scan, odom = of.get(Role.SCAN), of.get(Role.ODOMETRY)
    if scan is not None:
        report.clock = clock_line(np.asarray(scan.stamps, dtype=np.int64), np.asarray(scan.log_times, dtype=np.int64),
                                  config.io.clock_mismatch_s)
    if scan is not None and odom is None and Role.ODOMETRY not in role_of.values():
        frames, _ = resolve_base_frame(tf, config.frames)
        poses, _ = tf_odometry(tf, frames.odom, frames.base_link)
        odom = _TopicStats(stamps=[p.stamp_ns for p in poses], log_times=[p.log_time_ns for p in poses]) \
            if poses else None
    lags = None if scan is None or odom is None else clock_lags_s(scan.stamps, scan.log_times, odom.stamps,
                                                                  odom.log_times, config.io.clock_mismatch_s)
    if scan is not None and lags is None:
        stepped, note = clock_fault((scan.stamps, scan.log_times, odom.stamps if odom is not None else [],
                                     odom.log_times if odom is not None else []), config.io)
        if stepped:
            report.clock = "log times: the header stamps step (Problems)"
        if note:
            report.problems.append(Problem(Severity.WARNING, None, note))
    if lags is not None:
        report.clock = "log times: the scan and odometry header stamps are on different clocks (Problems)"
        report.problems.append(Problem(
            Severity.WARNING, None, f"scan and odometry header stamps are on different clocks (median stamp − log "
                                    f"time {lags[0]:+.3f} s and {lags[1]:+.3f} s): map and localize time them by "
                                    f"their log times"))
