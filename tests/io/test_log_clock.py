"""The recorder's clock against the stamps' (sim time at a real-time factor): both directions, any factor."""

from __future__ import annotations

import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from doorbatch.io.log_clock import LogClock

WALL = 1_700_000_000 * 10**9


@given(st.floats(0.2, 3.0), st.floats(0.0, 1.0), st.integers(0, 50))
@example(2.8349372769215733, 0.140625, 0)
def test_a_clock_at_a_real_time_factor_maps_both_ways(factor: float, where: float, beyond: int) -> None:
    stamps = 500_000_000 + np.arange(0, 100) * 100_000_000  # sim time, 10 Hz
    logged = WALL + np.round((stamps - stamps[0]) / factor).astype(np.int64)  # the recorder's clock
    clock = LogClock.of_pairs(logged, stamps, 1.0)
    s = int(stamps[0] + where * (stamps[-1] - stamps[0]))
    g = int(WALL + round((s - stamps[0]) / factor))
    # the pairs' log times are rounded to the nanosecond: a stamp read back from one carries that rounding times
    # the factor (3 ns at factor 2.83, which hypothesis found once), a log time it over the factor
    assert abs(clock.stamp_at(g) - s) <= 2 + factor and abs(clock.log_time_at(s) - g) <= 2 + 1 / factor
    after = int(stamps[-1]) + beyond * 10**6  # beyond the pairs: the last pair's gap
    assert clock.log_time_at(after) == after + int(logged[-1] - stamps[-1])


def test_one_clock_is_the_identity() -> None:
    stamps = WALL + np.arange(10) * 100_000_000
    clock = LogClock.of_pairs(stamps + 3_000_000, stamps, 1.0)  # 3 ms of latency: one clock
    assert clock.offset_ns == 0 and clock.log_time_at(int(stamps[3])) == int(stamps[3])
    assert LogClock.constant(5).log_time_at(10) == 15 and LogClock.constant(5).stamp_at(15) == 10
