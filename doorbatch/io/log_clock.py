"""The recorder's clock against a log's header stamps.

A bag records each message at its log time (the recorder's clock) while the message's header carries the stamp of
its own clock: the same clock on a real robot, Gazebo's sim time in a simulated run recorded on wall-clock time.
Sim time runs at the simulator's real-time factor, so the gap between the two clocks grows or shrinks through a
run. :class:`LogClock` holds the scans' (log time, stamp) pairs and maps either way by interpolating between them
(beyond them, the nearest pair's gap), relative to the first pair so that float64 keeps the nanoseconds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import numpy.typing as npt

Int64Array = npt.NDArray[np.int64]


def _empty() -> Int64Array:
    return np.zeros(0, dtype=np.int64)


def _map(x: int, xs: Int64Array, ys: Int64Array) -> int:
    """y at x, interpolated between the pairs (xs increasing), the nearest pair's gap beyond them."""
    if x <= xs[0] or x >= xs[-1]:
        k = 0 if x <= xs[0] else -1
        return int(x + (int(ys[k]) - int(xs[k])))
    x0, y0 = int(xs[0]), int(ys[0])
    return y0 + round(float(np.interp(x - x0, (xs - x0).astype(np.float64), (ys - y0).astype(np.float64))))


@dataclass(frozen=True)
class LogClock:
    """(log time, stamp) pairs, sorted by log time; none with ``offset_ns`` 0: one clock (the identity)."""

    log_ns: Int64Array = field(default_factory=_empty)
    stamp_ns: Int64Array = field(default_factory=_empty)
    offset_ns: int = 0  # the median log time − stamp (0: one clock)

    @classmethod
    def of_pairs(cls, log_ns: npt.ArrayLike, stamp_ns: npt.ArrayLike, mismatch_s: float) -> LogClock:
        """The clock of these pairs when their median gap exceeds ``mismatch_s``, else the identity."""
        g = np.asarray(log_ns, dtype=np.int64)
        t = np.asarray(stamp_ns, dtype=np.int64)
        if not g.size:
            return cls()
        offset = int(np.median(g - t))
        if abs(offset) <= mismatch_s * 1e9:
            return cls()
        order = np.argsort(g, kind="stable")
        return cls(g[order], t[order], offset)

    @classmethod
    def constant(cls, offset_ns: int) -> LogClock:
        """Two clocks a fixed ``offset_ns`` apart (log time = stamp + offset)."""
        return cls(np.zeros(1, dtype=np.int64) + offset_ns, np.zeros(1, dtype=np.int64), offset_ns)

    def stamp_at(self, log_time_ns: int) -> int:
        """The stamps' clock at a log time."""
        return log_time_ns if not self.log_ns.size else _map(log_time_ns, self.log_ns, self.stamp_ns)

    @cached_property
    def _by_stamp(self) -> tuple[Int64Array, Int64Array]:
        """The pairs sorted by stamp (once: :meth:`log_time_at` runs per annotation)."""
        order = np.argsort(self.stamp_ns, kind="stable")
        return self.stamp_ns[order], self.log_ns[order]

    def log_time_at(self, stamp_ns: int) -> int:
        """The recorder's clock at a stamp."""
        return stamp_ns if not self.log_ns.size else _map(stamp_ns, *self._by_stamp)


def long_gaps(periods_ns: npt.ArrayLike, factor: float, min_periods: int = 10) -> npt.NDArray[np.bool_]:
    """Which periods between consecutive messages are gaps: longer than ``factor`` × their median (a topic's
    nominal period); none with fewer than ``min_periods`` periods, whose median says little."""
    periods = np.asarray(periods_ns, dtype=np.float64).reshape(-1)
    if periods.size < min_periods:
        return np.zeros(periods.size, dtype=bool)
    nominal = float(np.median(periods))
    return periods > factor * nominal if nominal > 0 else np.zeros(periods.size, dtype=bool)
