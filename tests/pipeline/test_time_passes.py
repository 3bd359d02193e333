"""mapping.pass_duration_s: one log cut into passes by time."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig
from doorbatch.io.log_writer import LogWriter
from doorbatch.io.mapdir import read_door_set
from doorbatch.io.reader import open_log
from doorbatch.io.recording import load_recording
from doorbatch.io.sim_truth import read_truth
from doorbatch.pipeline.evaluate.door_map import score_doors, truth_doors
from doorbatch.pipeline.time_passes import pass_bounds, split_into_passes
from tests.conftest import REPO

SAMPLE_LOGS = REPO / "datasets" / "sample" / "logs"
S = 1_000_000_000


def test_pass_bounds_known_answers() -> None:
    stamps = np.arange(0, 100, dtype=np.int64) * S // 10  # 10 Hz over 9.9 s
    assert pass_bounds(stamps, 0.0) == [(0, 100)]
    assert pass_bounds(stamps, 5.0) == [(0, 50), (50, 100)]
    assert pass_bounds(stamps, 4.0) == [(0, 40), (40, 100)]  # it ends 1.9 s into [8, 12) s: that piece joins
    assert pass_bounds(stamps, 3.0) == [(0, 30), (30, 60), (60, 100)]  # 0.9 s into [9, 12) s
    assert pass_bounds(stamps, 3.2) == [(0, 32), (32, 64), (64, 100)]  # 0.3 s into [9.6, 12.8) s
    assert pass_bounds(stamps, 2.5) == [(0, 25), (25, 50), (50, 75), (75, 100)]  # 2.4 s into [7.5, 10) s: its own
    gap = np.concatenate([stamps[:20], stamps[60:]])  # no scans from 2 to 6 s: no pass there
    assert pass_bounds(gap, 2.0) == [(0, 20), (20, 40), (40, 60)]
    assert pass_bounds(gap[:21], 2.0) == [(0, 20), (20, 21)]  # 0 s into [6, 8), but 4 s after the pass before


@given(st.lists(st.integers(0, 10**11), min_size=1, max_size=200), st.floats(0.1, 50.0))
def test_pass_bounds_cut_the_scans_into_consecutive_passes_of_at_most_one_and_a_half_durations(
        offsets: list[int], pass_s: float) -> None:
    stamps = np.sort(np.array(offsets, dtype=np.int64))
    bounds = pass_bounds(stamps, pass_s)
    assert bounds[0][0] == 0 and bounds[-1][1] == stamps.shape[0]
    assert all(a < b for a, b in bounds) and all(b == c for (_, b), (c, _) in itertools.pairwise(bounds))
    spans = [(stamps[b - 1] - stamps[a]) / 1e9 for a, b in bounds]
    assert all(s < pass_s * (1 + 1e-9) for s in spans[:-1])
    assert spans[-1] < 1.5 * pass_s * (1 + 1e-9)


def test_pieces_hold_their_scans_colours_and_poses() -> None:
    rec = load_recording(SAMPLE_LOGS / "map_pass1.mcap", DoorbatchConfig(), with_colors=True)
    pieces = split_into_passes([rec], 15.0)
    assert [len(p.scans) for p in pieces] and sum(len(p.scans) for p in pieces) == len(rec.scans)
    assert np.array_equal(np.concatenate([p.scans.stamps_ns for p in pieces]), rec.scans.stamps_ns)
    assert pieces[0].warnings == rec.warnings and all(p.warnings == [] for p in pieces[1:])
    assert pieces[1].path.startswith(f"{rec.path} [15.")
    for p in pieces:
        assert p.colors is not None and len(p.colors) == len(p.scans)
        assert p.odometry is not None and rec.odometry is not None
        # every scan of the piece lies within its odometry, so poses interpolate as in the whole log
        assert p.odometry.stamps_ns[0] <= p.scans.stamps_ns[0] and p.odometry.stamps_ns[-1] >= p.scans.stamps_ns[-1]
    assert split_into_passes([rec], 0.0)[0] is rec


def test_one_log_of_three_passes_cut_by_time_finds_the_doors_that_moved(tmp_path: Path) -> None:
    """The sample's three passes as one log: as one pass, no door moved within it, so the grid stage finds none;
    cut into passes of 47 s (the passes last 44-47 s), every door that moved between passes, as from three logs."""
    one = tmp_path / "one.mcap"
    with LogWriter(one) as writer:
        for k in (1, 2, 3):
            with open_log(SAMPLE_LOGS / f"map_pass{k}.mcap") as reader:
                for raw in reader.raw_messages():
                    writer.write_raw(raw)
    truth, moved = truth_doors(read_truth(SAMPLE_LOGS / "map.truth.yaml"),
                               math.radians(DoorbatchConfig().doors.min_opening_deg))
    found = {}
    for pass_s in (0.0, 47.0):
        out = tmp_path / f"map{pass_s:g}"
        assert main(["map", str(one), "-o", str(out), "--stages", "grid", "-q", "--set",
                     f"mapping.pass_duration_s={pass_s}"]) == 0
        found[pass_s] = score_doors(read_door_set(out), truth, moved)
    assert found[0.0].recall == 0.0
    assert found[47.0].recall == 1.0 and found[47.0].precision == 1.0
    assert found[47.0].hinge_error_m.max() <= 0.10 and np.abs(found[47.0].length_error_m).max() <= 0.10


def test_pieces_of_one_log_chain_without_odometry_and_share_its_reference_coverage(tmp_path: Path) -> None:
    """Pieces of one log are one recording: without odometry (a handheld lidar matched at constant velocity)
    they were refused as disjoint frames; and a reference that covers two thirds of the log but none of its last
    piece made auto match scans for the whole map (coverage was judged per piece, not per log)."""
    from doorbatch.errors import PipelineError
    from doorbatch.pipeline.mapping import check_common_frame, choose_pose_source
    from tests.conftest import sample_messages, write_messages

    config = DoorbatchConfig()
    bare = [x for x in sample_messages(12) if x[0] not in ("/odom", "/tf", "/ground_truth")]
    rec = load_recording(write_messages(tmp_path / "bare.mcap", bare), config)
    pieces = split_into_passes([rec], 0.4)
    assert len(pieces) == 3 and pieces[1].odometry is None
    check_common_frame(pieces, "scanmatch", config)  # no error: one recording
    other = load_recording(write_messages(tmp_path / "other.mcap", bare), config)
    try:
        check_common_frame([rec, other], "scanmatch", config)
        raise AssertionError("two logs without odometry share no frame")
    except PipelineError:
        pass
    msgs = sample_messages(12)
    last_truth = sorted(t for topic, _, t, _ in msgs if topic == "/ground_truth")[8]
    partial = [x for x in msgs if x[0] != "/ground_truth" or x[2] < last_truth]  # truth for 8 of 12 scans
    rec = load_recording(write_messages(tmp_path / "partial.mcap", partial), config)
    assert choose_pose_source([rec], "auto", config)[0] == "reference"
    assert choose_pose_source(split_into_passes([rec], 0.4), "auto", config)[0] == "reference"


def test_a_pass_duration_that_is_not_a_finite_number_of_seconds_is_a_config_error(tmp_path: Path) -> None:
    for value in ("inf", "nan", "-1", "1e12"):
        assert main(["map", str(SAMPLE_LOGS / "map_pass1.mcap"), "-o", str(tmp_path / "m"), "--set",
                     f"mapping.pass_duration_s={value}"]) == 2, value
    # a window of 1 ns, not of 0 (a division by zero); the last scan is 0 ns into its window: it joins
    assert pass_bounds(np.arange(5, dtype=np.int64), 1e-12) == [(0, 1), (1, 2), (2, 3), (3, 5)]
