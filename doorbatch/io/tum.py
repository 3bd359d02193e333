"""TUM trajectory files (the format evo and the TUM RGB-D tools read), for planar poses.

One pose per line, fields separated by spaces: ``timestamp x y z qx qy qz qw``, the timestamp in seconds
with nine decimals (exact nanoseconds), the position in m, the orientation a unit quaternion. Lines
starting with ``#`` and blank lines are comments. Planar poses are written with z = 0 and a rotation about
z only; reading keeps x, y and the heading (yaw) of the quaternion.
"""

from __future__ import annotations

import decimal
import logging
from pathlib import Path
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_write_text

HEADER = "# timestamp x y z qx qy qz qw\n"
# Beyond these a trajectory is not planar, and scoring its (x, y, yaw) leaves something out: a warning says so.
PLANAR_Z_RANGE_M = 0.05  # a floor robot's height wanders by centimetres (a SLAM's z drift, a ramp)
PLANAR_TILT_DEG = 5.0  # a base rocks a few degrees; a handheld or legged recording more
NS_PER_S = 1_000_000_000
_INT64_MIN, _INT64_MAX = int(np.iinfo(np.int64).min), int(np.iinfo(np.int64).max)

log = logging.getLogger(__name__)

Int64Array = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]


class TumTrajectory(NamedTuple):
    """Planar poses read from a TUM file: stamps (ns), x and y (m), yaw (rad, in (−π, π])."""

    stamp_ns: Int64Array
    x: FloatArray
    y: FloatArray
    yaw: FloatArray


def format_stamp(stamp_ns: int) -> str:
    """Seconds with exactly nine decimals, from integer nanoseconds (``-1500000000`` → ``-1.500000000``)."""
    sign = "-" if stamp_ns < 0 else ""
    seconds, nanos = divmod(abs(stamp_ns), NS_PER_S)
    return f"{sign}{seconds}.{nanos:09d}"


def parse_stamp(text: str) -> int:
    """Integer nanoseconds from a decimal seconds string, exactly (more than nine decimals round half-even).

    Raises:
        ValueError: Not a finite decimal number.
    """
    try:
        seconds = decimal.Decimal(text)
    except decimal.InvalidOperation:
        raise ValueError(f"timestamp {text!r} is not a number") from None
    if not seconds.is_finite():
        raise ValueError(f"timestamp {text!r} is not finite")
    context = decimal.Context(prec=60, rounding=decimal.ROUND_HALF_EVEN)
    return int(context.multiply(seconds, decimal.Decimal(NS_PER_S)).to_integral_value(context=context))


def _planar_arrays(stamp_ns: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike, yaw: npt.ArrayLike
                   ) -> tuple[Int64Array, FloatArray, FloatArray, FloatArray]:
    """The four columns as 1-D arrays of one length, finite, stamps integer."""
    stamps = np.asarray(stamp_ns)
    if stamps.size and not np.issubdtype(stamps.dtype, np.integer):
        raise ValueError(f"stamp_ns must be integer nanoseconds, got dtype {stamps.dtype}")
    columns = [np.asarray(v, dtype=np.float64) for v in (x, y, yaw)]
    if any(c.ndim != 1 for c in [stamps, *columns]) or len({c.shape for c in [stamps, *columns]}) != 1:
        raise ValueError("stamp_ns, x, y, yaw must be 1-D arrays of one length")
    if not all(np.isfinite(c).all() for c in columns):
        raise ValueError("x, y, yaw must be finite")
    return stamps.astype(np.int64), columns[0], columns[1], columns[2]


def write_tum(path: Path, stamp_ns: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike,
              yaw: npt.ArrayLike) -> None:
    """Write planar poses as a TUM file atomically (z = 0, quaternion about z; floats exact, ``repr``).

    Args:
        path: The file to write (``trajectory.tum``).
        stamp_ns: (N,) int64 stamps in ns.
        x: (N,) x in m.
        y: (N,) y in m.
        yaw: (N,) heading in rad.

    Raises:
        ValueError: Arrays of different lengths, non-integer stamps, or non-finite values.
        OSError: The file cannot be written.
    """
    stamps, xs, ys, yaws = _planar_arrays(stamp_ns, x, y, yaw)
    qz, qw = np.sin(yaws / 2.0), np.cos(yaws / 2.0)
    rows = zip(stamps.tolist(), xs.tolist(), ys.tolist(), qz.tolist(), qw.tolist(), strict=True)
    lines = [f"{format_stamp(t)} {px!r} {py!r} 0.0 0.0 0.0 {z!r} {w!r}\n" for t, px, py, z, w in rows]
    atomic_write_text(path, HEADER + "".join(lines))


def _unit_hint(stamp: str) -> str:
    """What a stamp too large for seconds looks like by its size (a Unix time now is about 1.7e9 s), or ''."""
    size = abs(float(stamp))
    for exponent, unit in ((17, "nanoseconds"), (14, "microseconds"), (11, "milliseconds")):
        if size >= 10.0**exponent:
            return f" (TUM stamps are seconds; {stamp} looks like {unit})"
    return ""


def _parse_line(line: str) -> tuple[int, list[float]]:
    """Stamp (ns) and the seven floats of one pose line (space- or comma-separated: some tools write CSV)."""
    fields = line.replace(",", " ").split()
    if len(fields) != 8:
        raise ValueError(f"expected 8 fields (timestamp x y z qx qy qz qw), got {len(fields)}")
    values = [float(v) for v in fields[1:]]
    if not all(np.isfinite(values)):
        raise ValueError("non-finite position or quaternion")
    if sum(q * q for q in values[3:]) == 0.0:
        raise ValueError("quaternion has zero norm")
    stamp = parse_stamp(fields[0])
    if not _INT64_MIN <= stamp <= _INT64_MAX:
        raise ValueError(f"timestamp {fields[0]!r} is out of the int64 nanosecond range{_unit_hint(fields[0])}")
    return stamp, values


def _yaw(q: FloatArray) -> FloatArray:
    """Heading of (N, 4) quaternions (x, y, z, w), normalized first; in (−π, π]."""
    qx, qy, qz, qw = (q / np.linalg.norm(q, axis=1, keepdims=True)).T
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    wrapped: FloatArray = np.where(yaw <= -np.pi, yaw + 2.0 * np.pi, yaw)
    return wrapped


def read_tum(path: Path) -> TumTrajectory:
    """Read a TUM file into planar poses (z, roll and pitch are dropped; a warning is logged when z ranges over
    more than ``PLANAR_Z_RANGE_M`` or a pose tilts by more than ``PLANAR_TILT_DEG``).

    Raises:
        InputDataError: The file cannot be read, a line is malformed (names the file and line number), or the
            stamps go backwards (evo refuses such a trajectory too; the pose where they do is named).
    """
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputDataError(f"cannot read TUM file: {err}", path=path) from err
    stamps: list[int] = []
    values: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            stamp, floats = _parse_line(line)
        except ValueError as err:
            raise InputDataError(f"line {number}: {err}", path=path) from err
        stamps.append(stamp)
        values.append(floats)
    table = np.array(values, dtype=np.float64).reshape(-1, 7)
    stamp_ns = np.array(stamps, dtype=np.int64)
    back = np.flatnonzero(np.diff(stamp_ns) < 0)
    if back.size:
        before, after = (format_stamp(int(stamp_ns[k])) for k in (back[0], back[0] + 1))
        raise InputDataError(f"stamps go backwards {back.size} time(s), first after the {back[0] + 1}. pose "
                             f"({before} then {after} s); sort the file by time (sort -n)", path=path)
    _warn_if_not_planar(path, table)
    return TumTrajectory(stamp_ns, table[:, 0].copy(), table[:, 1].copy(),
                         _yaw(table[:, 3:]))


def _warn_if_not_planar(path: Path, table: FloatArray) -> None:
    """Log a warning when the poses (rows x y z qx qy qz qw) leave the plane: z ranges beyond
    ``PLANAR_Z_RANGE_M``, or the body's z axis tilts beyond ``PLANAR_TILT_DEG`` (cos tilt = 1 − 2(qx² + qy²))."""
    if not len(table):
        return
    z_range = float(np.ptp(table[:, 2]))
    q = table[:, 3:7] / np.linalg.norm(table[:, 3:7], axis=1, keepdims=True)
    tilt = float(np.degrees(np.arccos(np.clip(1.0 - 2.0 * (q[:, 0] ** 2 + q[:, 1] ** 2), -1.0, 1.0))).max())
    if z_range > PLANAR_Z_RANGE_M or tilt > PLANAR_TILT_DEG:
        log.warning("%s: not planar (z ranges over %.3f m, tilt up to %.1f°); scored as x, y and yaw only, as "
                    "doorbatch's runs are", path, z_range, tilt)
