"""CARMEN text logs (``.log``, ``.clf``, optionally gzipped): the classic public 2D laser datasets.

A CARMEN log is one message per line (``FLASER``, ``ODOM``, ``ROBOTLASER1``, ``PARAM``, ...). The reader
exposes it as synthetic ROS 2 topics built with the classes of :func:`ros2_typestore`, so that decoding,
role detection and MCAP conversion treat it like any bag:

==============  ==========================  =====================================================
topic           type                        from
==============  ==========================  =====================================================
/scan           sensor_msgs/LaserScan       FLASER and ROBOTLASER1 readings, frame ``laser`` (in a
                                            log with neither: RAWLASER1, the front laser's raw lines)
/odom           nav_msgs/Odometry           FLASER odometry fields (one per scan), ROBOTLASER1 robot
                                            pose, and ODOM lines (moved off the scans' stamps)
/ground_truth   nav_msgs/Odometry           TRUEPOS lines (the true robot pose CARMEN's simulator logs),
                                            else FLASER and ROBOTLASER1 laser pose (the corrected pose in
                                            corrected logs, the odometry in raw ones), moved back to base_link
/tf             tf2_msgs/TFMessage          odom→base_link, one per odometry pose
/tf_static      tf2_msgs/TFMessage          base_link→laser from the ``robot_frontlaser_*offset`` PARAMs
                                            (metres, metres, radians as CARMEN's simulator adds it), or
                                            without them from ROBOTLASER1's laser pose in its robot pose
==============  ==========================  =====================================================

The file has no index, so :meth:`CarmenReader.open` makes one pass over it: it validates every line,
counts messages, reads the PARAMs, finds the largest reading and repairs the time stamps
(:func:`repair_stamps`, then :func:`separate_odom_from_scan_stamps`, so that at a scan's stamp the
odometry is the scan's own field); :meth:`CarmenReader.raw_messages` then streams a second pass. A log cut short
(its last line cut mid-write, or a gzip stream that ends early) is read up to the cut, with a warning; every later
pass stops at the last line the pre-pass took. A malformed line before the last is an error.
"""

from __future__ import annotations

import gzip
import logging
import math
import zlib
from collections import Counter
from collections.abc import Collection, Iterator, Sequence
from dataclasses import dataclass
from decimal import ROUND_HALF_EVEN, Decimal, InvalidOperation
from pathlib import Path
from typing import IO, Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, IoConfig
from doorbatch.errors import LogReadError
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import relative
from doorbatch.io import ros_messages as rm
from doorbatch.io.decode import LASERSCAN, ODOMETRY, TF_MESSAGE
from doorbatch.io.reader import LogReader, RawMessage
from doorbatch.io.roles import TopicInfo

log = logging.getLogger(__name__)

Int64Array = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
Float32Array = npt.NDArray[np.float32]

SCAN_TOPIC = "/scan"
ODOM_TOPIC = "/odom"
REFERENCE_TOPIC = "/ground_truth"
TF_TOPIC = "/tf"
TF_STATIC_TOPIC = "/tf_static"
LASER_FRAME = "laser"
ENCODING = "carmen"

_FLASER = "FLASER"
_ODOM = "ODOM"
_ROBOTLASER1 = "ROBOTLASER1"
_RAWLASER1 = "RAWLASER1"
_TRUEPOS = "TRUEPOS"  # CARMEN's simulator: the true robot pose (and the odometry, which ODOM lines carry too)
_TIMED = frozenset({_FLASER, _ODOM, _ROBOTLASER1, _TRUEPOS})
_TIMED_RAW = frozenset({_ODOM, _RAWLASER1, _TRUEPOS})  # a log without FLASER and ROBOTLASER1 lines
# ROBOTLASER1 without offset PARAMs: its laser pose in its robot pose is the mount when it holds this still.
_MOUNT_TOLERANCE_M = 1e-3
_MOUNT_TOLERANCE_RAD = 1e-3
_MOUNT_MIN_LINES = 10
_MOUNT_MIN_TURN_RAD = math.radians(30.0)

_NS = 1_000_000_000
_MAX_STAMP_S = Decimal(2**62) / _NS  # beyond this a "stamp" is garbage, not a time
# Readings this close below the largest one are the scanner's no-return codes too (orebro: 32.759–32.767).
_NO_RETURN_BAND_M = 0.01
# Stamp repair: above this fraction of out-of-order or missing stamps, synthesize instead of nudging.
_MAX_NUDGED_FRACTION = 0.25
# Stamp repair: at or above this fraction of consecutive scans sharing one stamp, stamps are coarse.
_COARSE_FRACTION = 0.5
_MAX_PARAMS = ("robot_front_laser_max",)
_FULL_TURN = 2.0 * math.pi + 1e-6  # ROBOTLASER1 and RAWLASER1 angles are radians: no laser spans more


class _MalformedError(ValueError):
    """A line that does not have the layout of its keyword (turned into LogReadError with the line)."""


# --------------------------------------------------------------------------------------------------
# Pure helpers


def carmen_scan_geometry(n_readings: int, fov_deg: float) -> tuple[float, float]:
    """Beam angles of a FLASER scan: ``(angle_min, angle_increment)`` in radians.

    The readings span ``fov_deg`` centred on the laser's x axis. An odd count has a beam at each end
    (181 over 180° → −90°..+90° at 1°); an even count has one beam per increment of the field of view
    (180 over 180° → −90°..+89° at 1°; 360 → −90°..+89.5° at 0.5°).

    Raises:
        ValueError: no readings, or a field of view that is not positive.
    """
    if n_readings < 1:
        raise ValueError(f"a scan needs at least one reading, got {n_readings}")
    if not fov_deg > 0.0:
        raise ValueError(f"field of view must be positive, got {fov_deg}")
    fov = math.radians(fov_deg)
    if n_readings == 1:
        return 0.0, fov
    steps = n_readings - 1 if n_readings % 2 == 1 else n_readings
    return -fov / 2.0, fov / steps


def parse_stamp_ns(text: str) -> int:
    """A decimal seconds string → int nanoseconds, exactly (half-even); −1 if it cannot be a time.

    Negative, non-finite and absurdly large values (uninitialized memory in some logs) give −1.

    Raises:
        ValueError: the text is not a number.
    """
    try:
        value = Decimal(text)
    except InvalidOperation as err:
        raise ValueError(f"time stamp {text!r} is not a number") from err
    if not value.is_finite() or value < 0 or value > _MAX_STAMP_S:
        return -1
    return int((value * _NS).to_integral_value(rounding=ROUND_HALF_EVEN))


@dataclass(frozen=True, slots=True)
class StampRepair:
    """Repaired stamps (non-decreasing, one per timed line), how they were made, and what to tell."""

    stamps_ns: Int64Array
    method: str  # "logged" (unchanged), "nudged", "logger" (the logger's own stamps) or "synthesized"
    warnings: tuple[str, ...]


def heaviest_nondecreasing(values: Sequence[int], weights: Sequence[int]) -> list[int]:
    """Indices of a non-decreasing subsequence of ``values`` with the largest total weight.

    Dynamic programming over the values in index order with a Fenwick tree of prefix maxima over the
    value ranks: O(n log n). Ties go to the earliest chain, so the result is deterministic.
    """
    n = len(values)
    if n == 0:
        return []
    ranks = (np.unique(np.asarray(values), return_inverse=True)[1] + 1).tolist()
    size = max(ranks)
    tree_weight = [0] * (size + 1)
    tree_index = [-1] * (size + 1)
    total = [0] * n
    previous = [-1] * n
    for i, (rank, weight) in enumerate(zip(ranks, weights, strict=True)):
        best, best_index, k = 0, -1, rank
        while k > 0:  # the heaviest chain ending in a value <= this one
            if tree_weight[k] > best:
                best, best_index = tree_weight[k], tree_index[k]
            k -= k & -k
        total[i], previous[i] = best + weight, best_index
        k = rank
        while k <= size:
            if total[i] > tree_weight[k]:
                tree_weight[k], tree_index[k] = total[i], i
            k += k & -k
    chain: list[int] = []
    i = int(np.argmax(total))
    while i >= 0:
        chain.append(i)
        i = previous[i]
    return chain[::-1]


def _usable_indices(stamps: Int64Array, is_scan: BoolArray) -> tuple[Int64Array, int, int]:
    """Indices of the stamps kept as they are, and the counts of missing and out-of-order stamps.

    Missing: negative (unparseable as a time), or 0 after a positive stamp (leading zeros are a log that
    starts at t = 0). Out of order: valid stamps outside the heaviest non-decreasing run through them,
    where a scan outweighs all other lines together (keep as many scan stamps as possible, then as many
    of the others).
    """
    n = stamps.shape[0]
    missing = stamps < 0
    positive = np.flatnonzero(stamps > 0)
    if positive.size:
        missing |= (stamps == 0) & (np.arange(n) > positive[0])
    valid = np.flatnonzero(~missing)
    values = stamps[valid]
    if values.size < 2 or bool(np.all(np.diff(values) >= 0)):
        kept = valid
    else:
        heavy = int(np.count_nonzero(~is_scan)) + 1
        weights = np.where(is_scan[valid], heavy, 1).tolist()
        kept = valid[np.asarray(heaviest_nondecreasing(values.tolist(), weights), dtype=np.int64)]
    return kept.astype(np.int64), int(missing.sum()), int(valid.size - kept.size)


def _synthesize(n: int, is_scan: BoolArray, t0_ns: int, period_s: float) -> Int64Array:
    """Scan k at ``t0 + k·period``; other lines spread evenly between the scans around them."""
    scans = np.flatnonzero(is_scan)
    if scans.size == 0:
        position = np.arange(n, dtype=np.float64)
    else:
        xp = np.concatenate([[-1.0], scans.astype(np.float64), [float(n)]])
        fp = np.arange(-1.0, scans.size + 1.0)
        position = np.interp(np.arange(n, dtype=np.float64), xp, fp)
    offsets = np.rint((position - position[0]) * (period_s * _NS)).astype(np.int64)
    return np.maximum.accumulate(t0_ns + offsets)


def _coarse_fraction(scan_stamps: Int64Array) -> float:
    """The fraction of consecutive scans that share one stamp."""
    if scan_stamps.size < 2:
        return 0.0
    return float(np.mean(np.diff(scan_stamps) == 0))


def _interpolate_bad(stamps: Int64Array, kept: Int64Array) -> Int64Array:
    """Stamps not in ``kept`` replaced by linear interpolation (by line index) between kept neighbours."""
    n = stamps.shape[0]
    if kept.size in (0, n):
        return stamps.copy()
    base = int(stamps[kept[0]])  # interpolate offsets from it: exact in float64 for any log's span
    filled = np.interp(np.arange(n, dtype=np.float64), kept.astype(np.float64),
                       (stamps[kept] - base).astype(np.float64))
    repaired = base + np.rint(filled).astype(np.int64)
    repaired[kept] = stamps[kept]
    return np.maximum.accumulate(repaired)


@dataclass(frozen=True, slots=True)
class ScanStampSeparation:
    """Stamps with no ODOM line on a laser line's stamp, and the ODOM lines that could not be moved off it."""

    stamps_ns: Int64Array
    dropped: BoolArray  # ODOM lines still on a scan's stamp: not emitted
    n_restamped: int


def odom_at_scan_stamps(stamps_ns: Int64Array, is_scan: BoolArray, is_odom: BoolArray | None = None) -> BoolArray:
    """Which timed lines are ODOM lines (``is_odom``; None: every line that is not a scan) whose stamp equals a
    laser line's stamp."""
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    scan = np.asarray(is_scan, dtype=bool)
    odom = ~scan if is_odom is None else np.asarray(is_odom, dtype=bool)
    mask: BoolArray = odom & np.isin(stamps, stamps[scan])
    return mask


def separate_odom_from_scan_stamps(stamps_ns: Int64Array, is_scan: BoolArray, is_odom: BoolArray | None = None
                                   ) -> ScanStampSeparation:
    """Move ODOM lines off the laser lines' stamps, so that at a scan's instant its own odometry field wins.

    A laser line's odometry field is the odometry at its instant. In intel and aces, ODOM lines just before
    and after each scan carry the scan's stamp (the logger's stamps jitter by up to a second around the
    file order; in the corrected logs the ones before the scan are dead reckoning from the previous
    corrected pose, up to 0.54 m from the scan's field), and with equal stamps the interpolated odometry
    takes whichever comes first. Each such line gets a stamp by linear interpolation, by line index, between
    the nearest lines before and after it that are not such lines (file order is the order of the motion);
    one that still lands on a scan's stamp (no room between equal neighbours, or at either end) is dropped.

    Args:
        stamps_ns: non-decreasing stamps of the timed lines in file order (after :func:`repair_stamps`).
        is_scan: which of those lines are laser scans.
        is_odom: which are ODOM lines (None: every line that is not a scan); other lines (TRUEPOS) keep their stamps
            and bound the moved ones.
    """
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    scan = np.asarray(is_scan, dtype=bool)
    on_scan = odom_at_scan_stamps(stamps, scan, is_odom)
    if not on_scan.any():
        return ScanStampSeparation(stamps.copy(), on_scan, 0)
    moved = _interpolate_bad(stamps, np.flatnonzero(~on_scan).astype(np.int64))
    dropped = on_scan & odom_at_scan_stamps(moved, scan, is_odom)
    return ScanStampSeparation(moved, dropped, int(np.count_nonzero(on_scan & ~dropped)))


def _coarse_message(scan_stamps: Int64Array, coarse: float) -> str:
    steps = np.diff(np.unique(scan_stamps))
    resolution = float(np.median(steps)) / _NS if steps.size else 0.0
    per_scan = float(scan_stamps[-1] - scan_stamps[0]) / _NS / max(scan_stamps.size - 1, 1)
    return (f"time stamps are coarse: {coarse:.0%} of consecutive scans share a stamp (resolution about "
            f"{resolution:g} s; the logged stamps average {per_scan:.3g} s per scan)")


def _logger_stamps(logger_stamps_ns: Int64Array | None, is_scan: BoolArray, t0_ns: int) -> Int64Array | None:
    """The logger's stamps moved to start at ``t0_ns``, where they can stand in for the ipc stamps; else None.

    Usable: every timed line has one, they never go backwards, and no two scans share one (a clock finer than the
    scan period: not a coarse one too). They are the logger's receipt times, on one clock for every line, so the
    lines logged at one instant (a scan, its ODOM and TRUEPOS lines) stay within the logger's latency of each other.
    """
    if logger_stamps_ns is None:
        return None
    logger = np.asarray(logger_stamps_ns, dtype=np.int64).copy()
    if logger.shape != is_scan.shape or logger.size == 0:
        return None
    if logger.size > 2 and logger[-1] < 0 and bool(np.all(logger[:-1] >= 0)):
        # the last line's tail cut by a killed logger: a scan came a scan period after the scan before it; any
        # other line with the line before it
        scans = logger[:-1][is_scan[:-1]]
        cut_scan = bool(is_scan[-1]) and scans.size >= 2
        logger[-1] = int(scans[-1] + np.median(np.diff(scans))) if cut_scan else logger[-2]
    if bool(np.any(logger < 0)):
        return None
    if bool(np.any(np.diff(logger) < 0)) or bool(np.any(np.diff(logger[is_scan]) <= 0)):
        return None
    offsets = logger - logger[0]
    if t0_ns + int(offsets[-1]) > _MAX_STAMP_S * _NS:
        return None
    result: Int64Array = t0_ns + offsets
    return result


@dataclass(frozen=True, slots=True)
class ScanRate:
    """A log's scan period from its own stamps, and what it was measured over."""

    period_s: float
    span_s: float
    n_scans: int


def log_scan_rate(stamps_ns: Int64Array, kept: Int64Array, is_scan: BoolArray, io: IoConfig) -> ScanRate | None:
    """The scan period a log's stamps give: the time between two of its scans over the scans between them.

    The two are the first and the last kept scan whose stamp is above the kept scan before it: with coarse
    stamps (printed at 10 s resolution), the first scans logged after the printed stamp changed, so each is within a
    scan period of the stamp it shows; the log's first stamp is left out (the log may start anywhere in its
    interval). None where they span fewer than ``io.carmen_rate_min_scans`` scans or the period falls outside
    ``io.carmen_rate_min_period_s`` … ``io.carmen_rate_max_period_s`` (stamps in order by chance, not a clock).
    """
    scan_number = np.cumsum(is_scan) - 1  # of each timed line: the scans up to it, less one
    lines = kept[is_scan[kept]]
    values = stamps_ns[lines]
    steps = np.flatnonzero(np.diff(values) > 0) + 1
    if steps.size < 2:
        return None
    first, last = lines[steps[0]], lines[steps[-1]]
    n_scans = int(scan_number[last] - scan_number[first])
    span_s = float(stamps_ns[last] - stamps_ns[first]) / _NS
    if n_scans < io.carmen_rate_min_scans:
        return None
    period = span_s / n_scans
    if not io.carmen_rate_min_period_s <= period <= io.carmen_rate_max_period_s:
        return None
    return ScanRate(period, span_s, n_scans)


def repair_stamps(stamps_ns: Int64Array, is_scan: BoolArray, scan_period_s: float,
                  logger_stamps_ns: Int64Array | None = None, io: IoConfig | None = None) -> StampRepair:
    """Make the stamps of a CARMEN log's timed lines (in file order) usable and non-decreasing.

    - A few stamps out of order or missing (0 or garbage): they are replaced by linear interpolation
      between the nearest kept stamps before and after them ("nudged"); the kept ones are the longest
      non-decreasing run (scans first), so one wild stamp does not drag the others along.
    - More than a quarter of them bad, or coarse stamps (at least half of the consecutive scans share a
      stamp, as in logs printed at 10 s resolution): where the lines carry the logger's own stamps and those
      are usable (:func:`_logger_stamps`), every line takes its logger stamp, moved to start at t0 (the first
      kept stamp) ("logger"). Else scan k gets ``t0 + k·period`` and the other lines are spread evenly between
      the scans around them ("synthesized"), the period being the rate of the logged stamps themselves
      (:func:`log_scan_rate`), or ``scan_period_s`` where they give none. Either way one clock for every line:
      ODOM and TRUEPOS lines move with the scans, so a reference stays on the scans' clock.

    Args:
        stamps_ns: one stamp per timed line in file order, −1 where the line's stamp is not a time.
        is_scan: which of those lines are laser scans.
        scan_period_s: the scan period for synthesized stamps where the log gives no rate (the last resort).
        logger_stamps_ns: the logger's stamp of each of those lines, −1 where it has none (None: no line has).
        io: the limits on a log's own rate (``carmen_rate_*``); None: the defaults.
    """
    io = io or IoConfig()
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    is_scan = np.asarray(is_scan, dtype=bool)
    n = stamps.shape[0]
    if n == 0:
        return StampRepair(stamps.copy(), "logged", ())
    kept, n_missing, n_backward = _usable_indices(stamps, is_scan)
    repaired = _interpolate_bad(stamps, kept)
    bad = np.ones(n, dtype=bool)
    bad[kept] = False
    n_bad = int(np.count_nonzero(bad))
    n_scans = int(np.count_nonzero(is_scan))
    what = (f"{n_backward} out of order and {n_missing} missing (0 or not a time) of {n} stamps, "
            f"{int(np.count_nonzero(bad & is_scan))} of them scans")
    coarse = _coarse_fraction(repaired[is_scan]) if kept.size else 0.0
    too_many_bad = kept.size == 0 or n_bad > _MAX_NUDGED_FRACTION * n
    if too_many_bad or coarse >= _COARSE_FRACTION:
        why = f"time stamps are unusable: {what}" if too_many_bad else _coarse_message(repaired[is_scan], coarse)
        t0 = int(repaired[0]) if kept.size else 0
        logger = _logger_stamps(logger_stamps_ns, is_scan, t0)
        if logger is not None:
            span = float(logger[-1] - logger[0]) / _NS
            message = (f"{why}; took the logger's own time stamps instead (the last field of every line: in order, "
                       f"one per scan), {span:.6g} s over {n_scans} scans")
            return StampRepair(logger, "logger", (message,))
        rate = log_scan_rate(stamps, kept, is_scan, io)
        if rate is not None:
            period = rate.period_s
            source = f"the rate of the logged stamps, {rate.span_s:g} s over {rate.n_scans} scans"
        else:
            period = scan_period_s
            source = "io.carmen_scan_period_s: the logged stamps give no rate"
        message = f"{why}; synthesized them at {period:.6g} s per scan ({source}) over {n_scans} scans"
        return StampRepair(_synthesize(n, is_scan, t0, period), "synthesized", (message,))
    if n_bad:
        message = (f"time stamps repaired: {what}; replaced them by interpolation between their "
                   f"neighbours so that they are non-decreasing")
        return StampRepair(repaired, "nudged", (message,))
    return StampRepair(repaired, "logged", ())


# --------------------------------------------------------------------------------------------------
# Line parsing


@dataclass(frozen=True, slots=True)
class _Laser:
    """A FLASER, ROBOTLASER1 or RAWLASER1 line (RAWLASER1: no poses)."""

    ranges: Float32Array
    laser_pose: tuple[float, float, float] | None
    robot_pose: tuple[float, float, float] | None
    stamp_ns: int
    # ROBOTLASER1 and RAWLASER1 only: its own geometry, range and remissions.
    angle_min: float | None = None
    angle_increment: float | None = None
    range_max: float | None = None
    intensities: Float32Array | None = None
    tv: float = 0.0
    rv: float = 0.0
    logger_stamp_ns: int = -1  # the logger's own stamp (−1: none, or not a time)


@dataclass(frozen=True, slots=True)
class _Odom:
    """An ODOM line."""

    pose: tuple[float, float, float]
    tv: float
    rv: float
    stamp_ns: int
    logger_stamp_ns: int = -1


@dataclass(frozen=True, slots=True)
class _TruePose:
    """A TRUEPOS line: the simulator's true robot pose."""

    pose: tuple[float, float, float]
    stamp_ns: int
    logger_stamp_ns: int = -1


def _floats(parts: list[str], what: str, dtype: type[np.floating[Any]] = np.float64) -> npt.NDArray[Any]:
    try:
        return np.array(parts, dtype=dtype)
    except ValueError as err:
        bad = next((p for p in parts if not _is_number(p)), "?")
        raise _MalformedError(f"{what}: {bad!r} is not a number") from err


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _count(text: str, what: str) -> int:
    try:
        value = int(text)
    except ValueError as err:
        raise _MalformedError(f"{what} {text!r} is not an integer") from err
    if value < 0:
        raise _MalformedError(f"{what} {value} is negative")
    return value


def _pose(values: npt.NDArray[Any], what: str) -> tuple[float, float, float]:
    if not bool(np.all(np.isfinite(values))):
        raise _MalformedError(f"{what} is not finite")
    x, y, theta = values.tolist()
    return float(x), float(y), float(theta)


def _tail_stamp(parts: list[str], start: int, keyword: str) -> tuple[int, int]:
    """The two stamps after the fixed fields: ``timestamp [hostname logger_timestamp]``, as int ns.

    The first is the ipc stamp the message was published with, the line's time everywhere; the second the
    logger's own clock when it received the message (CARMEN's writelog.c: seconds since the logger started), −1
    where the line has none or it is not a time. The logger stamp is read leniently (nothing depends on it but
    the repair of unusable ipc stamps, :func:`repair_stamps`).
    """
    tail = len(parts) - start
    if not 1 <= tail <= 3:
        expected = f"{start + 1} to {start + 3}"
        raise _MalformedError(f"{keyword} line has {len(parts)} fields, its counts ask for {expected}")
    try:
        stamp = parse_stamp_ns(parts[start])
    except ValueError as err:
        raise _MalformedError(str(err)) from err
    logger = -1
    if tail == 3:
        try:
            logger = parse_stamp_ns(parts[start + 2])
        except ValueError:
            logger = -1
    return stamp, logger


def _parse_flaser(parts: list[str]) -> _Laser:
    """``FLASER n r1..rn x y theta odom_x odom_y odom_theta timestamp [hostname logger_timestamp]``."""
    if len(parts) < 2:
        raise _MalformedError("FLASER line has no reading count")
    n = _count(parts[1], "reading count")
    stamp, logger = _tail_stamp(parts, 2 + n + 6, _FLASER)
    ranges = _floats(parts[2 : 2 + n], "reading", np.float32)
    poses = _floats(parts[2 + n : 8 + n], "pose")
    return _Laser(ranges, _pose(poses[:3], "laser pose"), _pose(poses[3:], "odometry pose"), stamp,
                  logger_stamp_ns=logger)


def _parse_laser_with_header(parts: list[str], n_pose_fields: int) -> _Laser:
    """``ROBOTLASER1`` or ``RAWLASER1 type start fov res max_range accuracy remission_mode n r.. n_rem rem..``,
    then ``n_pose_fields`` (ROBOTLASER1: laser pose, robot pose, tv, rv, forward_safety, side_safety,
    turn_axis; RAWLASER1: none), then ``timestamp [host logger_timestamp]`` (CARMEN logger, writelog.c)."""
    keyword = parts[0]
    if len(parts) < 9:
        raise _MalformedError(f"{keyword} line has {len(parts)} fields, too few for its header")
    header = _floats(parts[1:8], "laser header")
    n = _count(parts[8], "reading count")
    if len(parts) < 10 + n:
        raise _MalformedError(f"{keyword} line has {len(parts)} fields, fewer than its {n} readings need")
    n_rem = _count(parts[9 + n], "remission count")
    rest = 10 + n + n_rem
    stamp, logger = _tail_stamp(parts, rest + n_pose_fields, keyword)
    ranges = _floats(parts[9 : 9 + n], "reading", np.float32)
    remissions = _floats(parts[10 + n : rest], "remission", np.float32)
    _, start, fov, res, max_range = header[:5].tolist()
    if not (math.isfinite(start) and math.isfinite(fov) and math.isfinite(res)):
        raise _MalformedError(f"{keyword} start angle, field of view or resolution is not finite")
    if res == 0.0:
        if n < 2 or fov == 0.0:
            raise _MalformedError(f"{keyword} has zero angular resolution and no field of view")
        res = fov / (n - 1)
    if abs(fov) > _FULL_TURN or abs(res) * max(n - 1, 0) > _FULL_TURN:
        raise _MalformedError(f"{keyword} field of view {fov:g} and resolution {res:g} span more than a full turn: "
                              "its angles must be in radians (they look like degrees)")
    laser_pose = robot_pose = None
    tv = rv = 0.0
    if n_pose_fields:
        poses = _floats(parts[rest : rest + 8], "pose")
        laser_pose, robot_pose = _pose(poses[:3], "laser pose"), _pose(poses[3:6], "robot pose")
        tv, rv = float(poses[6]), float(poses[7])
    return _Laser(
        ranges,
        laser_pose,
        robot_pose,
        stamp,
        angle_min=float(start),
        angle_increment=float(res),
        range_max=float(max_range) if math.isfinite(max_range) and max_range > 0 else None,
        intensities=remissions if n_rem == n else None,
        tv=tv,
        rv=rv,
        logger_stamp_ns=logger,
    )


def _parse_odom(parts: list[str]) -> _Odom:
    """``ODOM x y theta tv rv accel timestamp [hostname logger_timestamp]``."""
    stamp, logger = _tail_stamp(parts, 7, _ODOM)
    values = _floats(parts[1:7], "odometry")
    return _Odom(_pose(values[:3], "odometry pose"), float(values[3]), float(values[4]), stamp, logger)


def _parse_truepos(parts: list[str]) -> _TruePose:
    """``TRUEPOS true_x true_y true_theta odom_x odom_y odom_theta timestamp [hostname logger_timestamp]``."""
    stamp, logger = _tail_stamp(parts, 7, _TRUEPOS)
    return _TruePose(_pose(_floats(parts[1:4], "true pose"), "true pose"), stamp, logger)


def _parse(parts: list[str]) -> _Laser | _Odom | _TruePose:
    if parts[0] == _ODOM:
        return _parse_odom(parts)
    if parts[0] == _TRUEPOS:
        return _parse_truepos(parts)
    if parts[0] == _FLASER:
        return _parse_flaser(parts)
    return _parse_laser_with_header(parts, 11 if parts[0] == _ROBOTLASER1 else 0)


def base_from_laser(laser_pose: tuple[float, float, float],
                    offset: tuple[float, float, float]) -> tuple[float, float, float]:
    """The base_link pose whose laser (mounted at ``offset`` = x, y, yaw in base_link) is at ``laser_pose``."""
    lx, ly, ltheta = laser_pose
    ox, oy, oyaw = offset
    theta = ltheta - oyaw
    c, s = math.cos(theta), math.sin(theta)
    return lx - (c * ox - s * oy), ly - (s * ox + c * oy), math.atan2(math.sin(theta), math.cos(theta))


# --------------------------------------------------------------------------------------------------
# The reader


def open_carmen_text(path: Path) -> IO[str]:
    """A CARMEN log's text, gunzipped when its first bytes say gzip (whatever its name), undecodable bytes replaced
    (old logs carry Latin-1 comments)."""
    with path.open("rb") as f:
        gzipped = f.read(2) == b"\x1f\x8b"
    if gzipped:
        return gzip.open(path, "rt", encoding="utf-8", errors="replace")
    return path.open("r", encoding="utf-8", errors="replace")


class CarmenReader(LogReader):
    """A CARMEN text log (``.log``, ``.clf``, gzipped or not) as synthetic ROS 2 topics.

    After :meth:`open`: ``warnings`` (stamp repairs and other problems, for ``inspect``), ``params``
    (the PARAM lines), ``range_max_m`` and ``range_max_source`` (where the no-return value came from),
    ``stamp_method`` (``logged``, ``nudged``, ``logger`` or ``synthesized``) and ``ignored_lines`` (keyword → count).
    """

    storage = "carmen"

    def __init__(self, path: Path, config: DoorbatchConfig | None = None) -> None:
        super().__init__(path, config)
        self.params: dict[str, str] = {}
        self.ignored_lines: dict[str, int] = {}
        self.range_max_m = self.io_config.carmen_default_max_range_m
        self.range_max_source = "io.carmen_default_max_range_m"
        self.stamp_method = "logged"
        self.laser_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._stamps: Int64Array = np.empty(0, dtype=np.int64)
        self._dropped: BoolArray = np.empty(0, dtype=bool)  # ODOM lines at a scan's stamp (not emitted)
        self._topics: dict[str, TopicInfo] = {}
        self._fov_deg = self.io_config.carmen_fov_deg
        self._resolution_deg: float | None = None  # PARAM laser_front_laser_resolution
        self._timed = _TIMED  # the keywords this log's messages come from (_TIMED_RAW: RAWLASER1 scans)
        self._truth_lines = False  # the reference comes from TRUEPOS lines, not the laser lines' poses
        self._last_line: int | None = None  # the last line the pre-pass took: where the later passes stop

    # ---- reading lines


    def _lines(self, prepass: bool = False) -> Iterator[tuple[int, list[str]]]:
        """(line number, fields) of every line that is not blank or a comment.

        The pre-pass (``prepass``) reads to the end; a gzip stream that ends early there (a logger or a copy
        killed mid-write) ends it at the last complete line, with a warning, where any line came before the cut:
        those lines are usable, and a log's worth of them should not be refused for its last few bytes. The
        later passes stop at the last line the pre-pass took (``_last_line``), so that every pass sees the same
        lines: none reaches a cut, and a log still being written does not grow under the stamps of the first.
        A corrupt stream (bad data or checksum) stays an error.
        """
        limit = None if prepass else self._last_line
        lineno = 0
        try:
            with open_carmen_text(self.path) as text:
                for lineno, line in enumerate(text, start=1):
                    parts = line.split()
                    if parts and not parts[0].startswith("#"):
                        yield lineno, parts
                    if lineno == limit:
                        return
        except EOFError as err:
            if not prepass or lineno == 0:
                raise LogReadError(f"compressed log is truncated or corrupt after line {lineno}: {err}",
                                   path=self.path) from err
            self._warn(f"the compressed log ends early (cut after line {lineno}: {err}): read the {lineno} lines "
                       "before the cut")
        except (zlib.error, gzip.BadGzipFile) as err:
            raise LogReadError(f"compressed log is truncated or corrupt after line {lineno}: {err}",
                               path=self.path) from err
        except OSError as err:
            raise LogReadError(f"cannot read: {err.strerror or err}", path=self.path) from err

    def _error(self, lineno: int, parts: list[str], reason: str) -> LogReadError:
        preview = " ".join(parts[:4]) + (" ..." if len(parts) > 4 else "")
        return LogReadError(f"line {lineno}: {reason} ({preview!r})", path=self.path)

    # ---- the pre-pass

    def open(self) -> None:
        self.warnings, self.params = [], {}
        stamps: list[int] = []
        logger_stamps: list[int] = []
        is_scan: list[bool] = []
        counts: Counter[str] = Counter()
        ignored: Counter[str] = Counter()
        keywords: list[str] = []
        flaser_readings: Counter[int] = Counter()  # FLASER lines by their reading count
        mounts: list[tuple[float, float, float]] = []  # ROBOTLASER1: laser pose in robot pose
        robot_yaws: list[float] = []
        raw_error: LogReadError | None = None  # a malformed RAWLASER1 line matters only if those are the scans
        largest = -math.inf
        band: Float32Array = np.empty(0, dtype=np.float32)  # distinct readings near the largest
        last_taken = 0  # the last line read into the index: where the later passes stop
        cut: tuple[int, str, LogReadError] | None = None  # a malformed line: an error unless it is the last one
        for lineno, parts in self._lines(prepass=True):
            if cut is not None:  # a line follows it: not cut short by the end of the log, malformed
                if cut[1] != _RAWLASER1:
                    raise cut[2]
                raw_error, cut = raw_error or cut[2], None
                counts[_RAWLASER1] += 1
            keyword = parts[0]
            if keyword == "PARAM":
                if len(parts) < 3:
                    cut = (lineno, keyword, self._error(lineno, parts, "PARAM line needs a name and a value"))
                    continue
                self.params[parts[1]] = parts[2]
                last_taken = lineno
                continue
            if keyword not in _TIMED and keyword != _RAWLASER1:
                ignored[keyword] += 1
                last_taken = lineno
                continue
            try:
                record = _parse(parts)
            except _MalformedError as err:
                error = self._error(lineno, parts, str(err))
                error.__cause__ = err
                cut = (lineno, keyword, error)
                continue
            last_taken = lineno
            counts[keyword] += 1
            keywords.append(keyword)
            stamps.append(record.stamp_ns)
            logger_stamps.append(record.logger_stamp_ns)
            is_scan.append(isinstance(record, _Laser))
            if keyword == _FLASER and isinstance(record, _Laser):
                largest, band = _update_band(largest, band, record.ranges)
                flaser_readings[record.ranges.shape[0]] += 1
            elif isinstance(record, _Laser) and record.laser_pose is not None and record.robot_pose is not None:
                mx, my, myaw = relative(record.robot_pose, record.laser_pose).tolist()
                mounts.append((mx, my, myaw))
                robot_yaws.append(record.robot_pose[2])
        raw_cut = 0  # a cut RAWLASER1 line: counted among those lines as before, but no scan
        if cut is not None:
            if cut[1] == _RAWLASER1:
                counts[_RAWLASER1] += 1
                raw_cut = 1
            self._warn(f"the last line is cut short ({cut[2].reason}), as a logger killed mid-write leaves it: "
                       f"dropped it, read the {cut[0] - 1} lines before it")
        self._last_line = last_taken
        n_scans = counts[_FLASER] + counts[_ROBOTLASER1]
        if n_scans == 0 and counts[_RAWLASER1]:
            # Choice: the raw front laser only where no line carries it with poses (the logger writes both).
            if raw_error is not None:
                raise raw_error
            self._timed, n_scans = _TIMED_RAW, counts[_RAWLASER1] - raw_cut
            self._warn(f"scans from {n_scans} RAWLASER1 lines (no FLASER or ROBOTLASER1): they carry no pose, "
                       f"so the log has {'odometry from its ODOM lines' if counts[_ODOM] else 'no odometry'} "
                       f"and {'a reference from its TRUEPOS lines only' if counts[_TRUEPOS] else 'no reference'}")
        elif counts[_RAWLASER1]:
            ignored[_RAWLASER1] = counts[_RAWLASER1]
        if n_scans == 0:
            raise LogReadError("no laser scans (FLASER, ROBOTLASER1 or RAWLASER1 lines) in this CARMEN log",
                               path=self.path)
        keep = [k in self._timed for k in keywords]
        stamps = [t for t, k in zip(stamps, keep, strict=True) if k]
        logger_stamps = [t for t, k in zip(logger_stamps, keep, strict=True) if k]
        is_scan = [v for v, k in zip(is_scan, keep, strict=True) if k]
        self.ignored_lines = dict(sorted(ignored.items()))
        self._read_params(counts[_FLASER], largest, band, mounts, robot_yaws)
        self._check_flaser_fov(flaser_readings)
        repair = repair_stamps(np.array(stamps, dtype=np.int64), np.array(is_scan, dtype=bool),
                               self.io_config.carmen_scan_period_s, np.array(logger_stamps, dtype=np.int64),
                               self.io_config)
        self._stamps = repair.stamps_ns
        self.stamp_method = repair.method
        for message in repair.warnings:
            self._warn(message)
        # Choice: re-stamped by file order, not dropped: they record motion just before or after the scan. Not
        # for RAWLASER1 scans: they carry no odometry of their own, so an ODOM line at their stamp is the only one.
        scan_lines = np.array(is_scan, dtype=bool) & (self._timed is not _TIMED_RAW)
        # Only ODOM lines move: a TRUEPOS line keeps its stamp (the true pose at a scan's instant is what a reference
        # should give there) and bounds the ODOM lines around it, so the lines stay in time order.
        odom_lines = np.array([k == _ODOM for k, k_kept in zip(keywords, keep, strict=True) if k_kept], dtype=bool)
        separation = separate_odom_from_scan_stamps(self._stamps, scan_lines, odom_lines)
        self._stamps, self._dropped = separation.stamps_ns, separation.dropped
        n_dropped = int(np.count_nonzero(self._dropped))
        if separation.n_restamped or n_dropped:
            self._warn(f"{separation.n_restamped + n_dropped} of {counts[_ODOM]} ODOM lines share a scan's time "
                       f"stamp (the scan's own odometry field is the odometry at that instant): re-stamped "
                       f"{separation.n_restamped} by interpolation between their neighbours in file order, "
                       f"dropped {n_dropped}")
        n_posed = 0 if self._timed is _TIMED_RAW else n_scans  # scans whose line carries poses
        n_odom = n_posed + counts[_ODOM] - n_dropped
        self._truth_lines = counts[_TRUEPOS] > 0
        n_reference = counts[_TRUEPOS] if self._truth_lines else n_posed
        if self._truth_lines:
            self._warn(f"the reference is the {counts[_TRUEPOS]} TRUEPOS lines (a simulator's true poses), not the "
                       f"laser lines' poses")
        topics = [TopicInfo(SCAN_TOPIC, LASERSCAN, n_scans, ENCODING),
                  TopicInfo(ODOM_TOPIC, ODOMETRY, n_odom, ENCODING),
                  TopicInfo(REFERENCE_TOPIC, ODOMETRY, n_reference, ENCODING),
                  TopicInfo(TF_TOPIC, TF_MESSAGE, n_odom, ENCODING),
                  TopicInfo(TF_STATIC_TOPIC, TF_MESSAGE, 1, ENCODING)]
        self._topics = {t.name: t for t in topics if t.count}

    def _warn(self, message: str) -> None:
        """A repair or problem, for ``inspect`` and the manifests of the commands that read the log (which
        print it once; logged here at debug level only)."""
        log.debug("%s: %s", self.path, message)
        self.warnings.append(f"{self.path}: {message}")

    def _param_float(self, name: str) -> float | None:
        text = self.params.get(name)
        if text is None:
            return None
        try:
            value = float(text)
        except ValueError as err:
            raise LogReadError(f"PARAM {name} {text!r} is not a number", path=self.path) from err
        if not math.isfinite(value):
            raise LogReadError(f"PARAM {name} {text!r} is not finite", path=self.path)
        return value

    def _read_params(self, n_flaser: int, largest: float, band: Float32Array,
                     mounts: Sequence[tuple[float, float, float]] = (), robot_yaws: Sequence[float] = ()) -> None:
        """Laser offset, FLASER field of view and the no-return value, from PARAMs or the readings.

        The angular offset is in radians: CARMEN's simulator and robot module add it to the heading as it
        is (only the laser's field of view and resolution PARAMs are in degrees). Without any offset PARAM,
        ROBOTLASER1 lines give the mount as their laser pose in their robot pose, when that holds still
        over the log while the robot turned (``_MOUNT_MIN_LINES`` lines over ``_MOUNT_MIN_TURN_RAD`` of heading:
        a rigid mount, not a coincidence); in a corrected log the laser pose is the corrected one and it does
        not hold still."""
        offsets = [self._param_float(f"robot_frontlaser_{name}")
                   for name in ("offset", "side_offset", "angular_offset")]
        self.laser_offset = (offsets[0] or 0.0, offsets[1] or 0.0, offsets[2] or 0.0)
        turned = float(np.ptp(np.unwrap(np.asarray(robot_yaws)))) if len(robot_yaws) else 0.0
        if all(v is None for v in offsets) and len(mounts) >= _MOUNT_MIN_LINES and turned >= _MOUNT_MIN_TURN_RAD:
            m = np.array(mounts)
            turn = wrap_angle(m[:, 2] - m[0, 2])  # about the first (±π)
            if (np.ptp(m[:, :2], axis=0).max() <= _MOUNT_TOLERANCE_M
                    and np.ptp(turn) <= _MOUNT_TOLERANCE_RAD):
                x, y = np.median(m[:, :2], axis=0).tolist()
                yaw = float(m[0, 2] + np.median(turn))
                self.laser_offset = (float(x), float(y), float(wrap_angle(yaw)))
                if any(abs(v) > 0 for v in self.laser_offset):
                    log.info("%s: laser mount (%.3f m, %.3f m, %.4f rad) from the ROBOTLASER1 poses",
                             self.path, *self.laser_offset)
        names = [*_MAX_PARAMS, *sorted(p for p in self.params if p.startswith("laser_")
                                         and "max_range" in p and "rear" not in p)]
        for name in names:
            value = self._param_float(name)
            if value is not None and value > 0:
                self.range_max_m, self.range_max_source = value, f"PARAM {name}"
                break
        else:
            if n_flaser and largest > 0:
                self.range_max_m = float(band.min())
                self.range_max_source = (
                    f"largest reading {largest:g} m" + ("" if band.size == 1 else
                                                        f" (and readings down to {band.min():g} m)")
                )
                log.info("%s: no max-range PARAM; %s is the no-return value", self.path, self.range_max_source)
        resolution = self._param_float("laser_front_laser_resolution")
        self._resolution_deg = resolution if resolution is not None and resolution > 0 else None
        fov = self._param_float("laser_front_laser_fov")  # degrees, as carmen.ini gives it
        if fov is not None and 0.0 < fov <= 360.0:
            self._fov_deg = fov

    def _check_flaser_fov(self, readings: Counter[int]) -> None:
        """A warning when FLASER lines have a reading count that no paper-era SICK scanner gives (180, 181, 360,
        361) and no PARAM states the field of view or resolution: their angles are then only the configured
        ``io.carmen_fov_deg``'s guess (a 541-beam 270° laser squeezed into 180° maps nothing)."""
        if self._resolution_deg is not None or "laser_front_laser_fov" in self.params or not readings:
            return
        n = readings.most_common(1)[0][0]
        if n not in (180, 181, 360, 361):
            self._warn(f"FLASER lines have {n} readings and no laser_front_laser_fov or laser_front_laser_resolution "
                       f"PARAM: taken to span {self._fov_deg:g}° (io.carmen_fov_deg); set it if the laser spans "
                       "another field of view")

    def _flaser_geometry(self, n: int) -> tuple[float, float]:
        fov = self._fov_deg
        if self._resolution_deg is not None:
            steps = n - 1 if n % 2 == 1 else n
            if 0 < self._resolution_deg * steps <= 360.0:
                fov = self._resolution_deg * steps
        return carmen_scan_geometry(max(n, 1), fov)

    def close(self) -> None:
        """Nothing stays open between calls: each pass opens the file itself."""

    @property
    def topics(self) -> dict[str, TopicInfo]:
        return self._topics

    @property
    def start_ns(self) -> int:
        return int(self._stamps[0]) if self._stamps.size else 0

    @property
    def end_ns(self) -> int:
        return int(self._stamps[-1]) if self._stamps.size else 0

    # ---- the streaming pass

    def _raw(self, topics: Collection[str] | None, start_ns: int | None, stop_ns: int | None
             ) -> Iterator[RawMessage]:
        wanted = set(self._topics) if topics is None else set(topics) & set(self._topics)
        if not wanted or not self._stamps.size:
            return
        lo = self.start_ns if start_ns is None else start_ns
        hi = None if stop_ns is None else stop_ns
        frames = self.frames
        first = self.start_ns
        if TF_STATIC_TOPIC in wanted and lo <= first and (hi is None or first < hi):
            ox, oy, oyaw = self.laser_offset
            static = rm.tf_message([rm.planar_transform(first, frames.base_link, LASER_FRAME, ox, oy, oyaw)])
            yield RawMessage(TF_STATIC_TOPIC, TF_MESSAGE, first, static, False)
        odometry_wanted = bool(wanted & {ODOM_TOPIC, TF_TOPIC})
        laser_wanted = bool(wanted & {SCAN_TOPIC, REFERENCE_TOPIC}) or odometry_wanted
        index = -1
        for lineno, parts in self._lines():
            if parts[0] not in self._timed:
                continue
            index += 1
            if index >= self._stamps.size:
                raise LogReadError(f"line {lineno}: the log changed since it was opened", path=self.path)
            stamp = int(self._stamps[index])
            if self._dropped[index]:
                continue
            if stamp < lo:
                continue
            if hi is not None and stamp >= hi:
                break
            is_odom = parts[0] == _ODOM
            if parts[0] == _TRUEPOS and REFERENCE_TOPIC not in wanted:
                continue
            if (is_odom and not odometry_wanted) or (not is_odom and not laser_wanted):
                continue
            try:
                record = _parse(parts)
            except _MalformedError as err:
                raise self._error(lineno, parts, str(err)) from err
            yield from self._messages_of(record, stamp, wanted)

    def _messages_of(self, record: _Laser | _Odom | _TruePose, stamp: int, wanted: set[str]
                     ) -> Iterator[RawMessage]:
        frames = self.frames
        if isinstance(record, _TruePose):
            yield RawMessage(REFERENCE_TOPIC, ODOMETRY, stamp, rm.odometry(stamp, frames.map, frames.base_link,
                                                                            *record.pose), False)
            return
        if isinstance(record, _Odom):
            odom_pose, tv, rv = record.pose, record.tv, record.rv
        else:
            if SCAN_TOPIC in wanted:
                yield RawMessage(SCAN_TOPIC, LASERSCAN, stamp, self._scan(record, stamp), False)
            if record.robot_pose is None or record.laser_pose is None:  # RAWLASER1: the scan alone
                return
            odom_pose, tv, rv = record.robot_pose, record.tv, record.rv
        if ODOM_TOPIC in wanted:
            odom = rm.odometry(stamp, frames.odom, frames.base_link, *odom_pose, vx=tv, wz=rv)
            yield RawMessage(ODOM_TOPIC, ODOMETRY, stamp, odom, False)
        if TF_TOPIC in wanted:
            tf = rm.tf_message([rm.planar_transform(stamp, frames.odom, frames.base_link, *odom_pose)])
            yield RawMessage(TF_TOPIC, TF_MESSAGE, stamp, tf, False)
        if (isinstance(record, _Laser) and record.laser_pose is not None and REFERENCE_TOPIC in wanted
                and not self._truth_lines):
            pose = base_from_laser(record.laser_pose, self.laser_offset)
            ref = rm.odometry(stamp, frames.map, frames.base_link, *pose)
            yield RawMessage(REFERENCE_TOPIC, ODOMETRY, stamp, ref, False)

    def _scan(self, record: _Laser, stamp: int) -> Any:
        n = record.ranges.shape[0]
        if record.angle_min is not None and record.angle_increment is not None:
            angle_min, increment = record.angle_min, record.angle_increment
        else:
            angle_min, increment = self._flaser_geometry(n)
        range_max = record.range_max if record.range_max is not None else self.range_max_m
        return rm.laser_scan(stamp, LASER_FRAME, angle_min, increment, self.io_config.carmen_range_min_m, range_max,
                             record.ranges, record.intensities)


def _update_band(largest: float, band: Float32Array, ranges: Float32Array) -> tuple[float, Float32Array]:
    """Track the largest finite reading and the distinct readings within 1 cm below it."""
    finite = ranges[np.isfinite(ranges)]
    if finite.size == 0:
        return largest, band
    top = float(finite.max())
    if top < largest - _NO_RETURN_BAND_M:
        return largest, band
    largest = max(largest, top)
    floor = largest - _NO_RETURN_BAND_M
    merged = np.unique(np.concatenate([band, finite[finite >= floor]]))
    return largest, merged[merged >= floor]
