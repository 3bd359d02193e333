"""Header stamps that step against the recorder's clock (an NTP step), and scans stamped ahead of their odometry:
known stamp series with known answers, and a log whose stamps step, read end to end."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.io import ros_messages as m
from doorbatch.io.recording import clock_ahead_s, clock_restarts, clock_steps, load_recording
from tests.conftest import sample_messages

S = 1_000_000_000
T0 = 1_700_000_000 * S


def _series(n: int = 100, period_s: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    log = T0 + np.round(np.arange(n) * period_s * S).astype(np.int64)
    return log - 5_000_000, log  # stamps 5 ms before they are logged


@pytest.mark.parametrize("step_s", [2.0, -2.0, 0.3])
def test_a_stamp_clock_that_is_set_is_a_step_where_and_as_large_as_it_was_set(step_s: float) -> None:
    stamps, log = _series()
    stamps[40:] += round(step_s * S)
    ((index, found),) = clock_steps(stamps, log, 0.1)
    assert index == 40 and found == pytest.approx(step_s)


def test_late_arrivals_dropouts_a_paused_or_slow_simulator_and_jitter_are_no_steps() -> None:
    stamps, log = _series()
    late = log.copy()
    late[30] += 600_000_000  # logged 0.6 s late: its log time is out of step, its stamp is not
    dropout_stamps, dropout_log = np.delete(stamps, range(50, 70)), np.delete(log, range(50, 70))  # 2 s, both clocks
    paused = log.copy()
    paused[60:] += 5 * S  # a paused simulator: log time runs on, sim time does not
    sim = T0 + np.round(np.arange(100) * 0.1 * S).astype(np.int64), T0 + np.round(np.arange(100) * 0.4 * S)
    jitter = stamps + np.random.default_rng(0).integers(-5_000_000, 5_000_000, stamps.size)
    swapped = stamps.copy()
    swapped[[20, 21]], swapped[[40, 43]] = swapped[[21, 20]], swapped[[43, 40]]  # logged in another order
    for series in ((stamps, late), (dropout_stamps, dropout_log), (stamps, paused), sim, (jitter, log),
                   (swapped, log)):
        assert clock_steps(*series, 0.1) == []


def test_log_times_that_keep_no_rate_and_a_late_last_message_tell_no_step() -> None:
    """A reviewer's cases: a recorder that received in bursts every 0.4 s, one that logged whole seconds (each with
    a dropout), and a scan logged 0.35 s late at the very end: each had been taken for a step, and the first two
    retimed good scans onto their log times (the second then refused as 'only 7 distinct stamps')."""
    stamps, log = _series()
    bursty = T0 + (np.arange(100) // 4 + 1) * 400_000_000 + np.arange(100) % 4 * 1_000_000  # 1 ms apart in a burst
    coarse = T0 + (np.arange(100) // 10) * S
    drop = np.r_[0:43, 45:100]  # two scans lost within one second
    late = log.copy()
    late[-1] += 350_000_000
    for series in ((stamps[drop], bursty[drop]), (stamps[drop], coarse[drop]), (stamps, late)):
        assert clock_steps(*series, 0.1) == []


def test_sim_time_that_drifts_against_the_log_tells_no_clock_ahead() -> None:
    """A simulator at real-time factor 0.5, its odometry starting 1 s after the first scan: one clock whose gap
    to the log time drifts, so medians over different spans differ (a reviewer's false 0.5 s warning)."""
    sim = T0 + np.round(np.arange(200) * 0.05 * S).astype(np.int64)
    log = T0 + np.round(np.arange(200) * 0.1 * S).astype(np.int64)
    assert clock_ahead_s(sim, log, sim[20:], log[20:], 0.05, 1.0) is None


def test_scans_stamped_ahead_of_their_odometry_are_told_by_how_much() -> None:
    stamps, log = _series()
    assert clock_ahead_s(stamps + 300_000_000, log, stamps, log, 0.05, 1.0) == pytest.approx(0.3)
    assert clock_ahead_s(stamps - 80_000_000, log, stamps, log, 0.05, 1.0) is None  # a laser's latency
    assert clock_ahead_s(stamps + 30_000_000, log, stamps, log, 0.05, 1.0) is None  # within jitter
    assert clock_ahead_s(stamps + 3 * S, log, stamps, log, 0.05, 1.0) is None  # two clocks: timed by log time


def test_a_log_whose_clock_steps_is_timed_by_its_log_times(write_log: Callable[..., Path]) -> None:
    """A helper's NTP step of +2 s 20 s into a log: the trajectory after it was 2 s late (1.4 m APE) and the run
    reported a gap the recording does not have; with -2 s the sorted scans interleaved. Both are now timed by
    their log times, with a warning."""
    messages = sample_messages(30)
    for _, _, t, msg in messages:
        header = getattr(msg, "header", None)
        if header is not None and t >= messages[0][2] + 1_500_000_000:  # every clock but the recorder's is set
            stamp = t + 2 * S
            msg.header = m.header(stamp, header.frame_id)
    rec = load_recording(write_log("stepped.mcap", messages), DoorbatchConfig())
    assert any("step by +2.00 s against the recorder's clock" in w and "timed by its log time" in w
               for w in rec.warnings)
    steps = np.diff(rec.scans.stamps_ns)
    assert steps.max() == steps.min() == 100_000_000  # no 2 s hole: the scans' log times, 0.1 s apart
    plain = load_recording(write_log("plain.mcap", sample_messages(30)), DoorbatchConfig())
    assert not any("header stamps step" in w or "runs ahead" in w for w in plain.warnings)


def test_a_simulator_relaunched_within_a_recording_is_a_restart_of_its_clock() -> None:
    """Gazebo relaunched 250 s of recording later: sim time starts again at 0 while the recorder's clock goes on.
    Found where it starts again; a message logged out of order, or one stamped 3 s late, is none."""
    sim = np.round(np.arange(100) * 0.1 * S).astype(np.int64) + S // 100
    stamps = np.r_[sim[:60], sim[:40]]
    log = T0 + np.r_[np.round(np.arange(60) * 0.1 * S), 250 * S + np.round(np.arange(40) * 0.1 * S)].astype(np.int64)
    ((index, back),) = clock_restarts(stamps, log, 1.0)
    assert index == 60 and back == pytest.approx(-5.9)
    one_late = sim.copy()
    one_late[50] -= 3 * S
    swapped = sim.copy()
    swapped[[20, 21]] = swapped[[21, 20]]
    plain_log = T0 + np.round(np.arange(100) * 0.1 * S).astype(np.int64)
    last_late = sim.copy()
    last_late[-1] -= 3 * S  # the last message stamped 3 s early (a reviewer's case): nothing after it to stay back
    for series in ((one_late, plain_log), (swapped, plain_log), (sim, plain_log), (last_late, plain_log)):
        assert clock_restarts(*series, 1.0) == []


def test_a_log_of_two_launches_is_timed_by_its_log_times(write_log: Callable[..., Path]) -> None:
    """hAL's one recording of two Gazebo launches: sorted by stamp, the second launch's scans interleaved with the
    first's (a smeared map and a 20 m trajectory, exit 0). Now every scan and pose is timed by its log time, in
    the order they were recorded, with a warning."""
    first, second = sample_messages(20), sample_messages(20)
    t_first, t_second = first[0][2], first[0][2] + 250 * S
    messages = list(first)
    for topic, msgtype, t, msg in second:
        header = getattr(msg, "header", None)
        if header is not None:
            msg.header = m.header(header.stamp.sec * S + header.stamp.nanosec - t_first + S // 100, header.frame_id)
        messages.append((topic, msgtype, t - t_first + t_second, msg))
    for k, (topic, msgtype, t, msg) in enumerate(messages[:len(first)]):
        header = getattr(msg, "header", None)
        if header is not None:  # the first launch's sim time from 0 too
            msg.header = m.header(header.stamp.sec * S + header.stamp.nanosec - t_first + S // 100, header.frame_id)
            messages[k] = (topic, msgtype, t, msg)
    rec = load_recording(write_log("relaunched.mcap", messages), DoorbatchConfig())
    assert any("go back by" in w and "relaunched" in w for w in rec.warnings)
    assert np.all(np.diff(rec.scans.stamps_ns) > 0) and len(rec.scans) == 40
    assert rec.scans.stamps_ns[20] - rec.scans.stamps_ns[19] > 200 * S  # the second launch after the first
