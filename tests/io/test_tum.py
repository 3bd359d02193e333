"""TUM trajectories: exact nanosecond stamps, planar poses, line-numbered errors."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.errors import InputDataError
from doorbatch.io.tum import format_stamp, parse_stamp, read_tum, write_tum

stamps_ns = st.integers(-(2**62), 2**62)


@given(stamp=stamps_ns)
def test_stamp_text_round_trips_exactly(stamp: int) -> None:
    text = format_stamp(stamp)
    assert len(text.split(".")[1]) == 9
    assert parse_stamp(text) == stamp


@pytest.mark.parametrize(
    ("text", "ns"),
    [("1305031102.175304", 1305031102175304000), ("1305031102.1753040001", 1305031102175304000),
     ("1.0000000005", 1000000000), ("1.0000000015", 1000000002), ("1.5e9", 1500000000000000000),
     ("-0.5", -500000000), ("42", 42000000000), (".25", 250000000)],
)
def test_parse_stamp_is_exact_decimal(text: str, ns: int) -> None:
    assert parse_stamp(text) == ns


@settings(max_examples=50, deadline=None)
@given(
    poses=st.lists(
        st.tuples(stamps_ns, st.floats(-1e6, 1e6), st.floats(-1e6, 1e6), st.floats(-math.pi, math.pi)),
        max_size=20,
    )
)
def test_write_read_round_trip(tmp_path_factory: pytest.TempPathFactory,
                               poses: list[tuple[int, float, float, float]]) -> None:
    path = tmp_path_factory.mktemp("tum") / "trajectory.tum"
    poses = sorted(poses, key=lambda p: p[0])  # a trajectory is in time order (read_tum refuses one that is not)
    stamp = np.array([p[0] for p in poses], dtype=np.int64)
    x, y, yaw = (np.array([p[k] for p in poses], dtype=np.float64) for k in (1, 2, 3))
    write_tum(path, stamp, x, y, yaw)
    back = read_tum(path)
    assert back.stamp_ns.dtype == np.int64
    assert np.array_equal(back.stamp_ns, stamp)
    assert np.array_equal(back.x, x)
    assert np.array_equal(back.y, y)
    angle_error = np.angle(np.exp(1j * (back.yaw - yaw)))
    assert np.all(np.abs(angle_error) < 1e-12)
    assert np.all((back.yaw > -math.pi) & (back.yaw <= math.pi))


def test_written_lines_have_eight_fields_planar_quaternion(tmp_path: Path) -> None:
    path = tmp_path / "t.tum"
    write_tum(path, np.array([1_700_000_000_123_456_789]), [1.5], [-2.0], [math.pi / 2])
    lines = path.read_text().splitlines()
    assert lines[0].startswith("#")
    fields = lines[1].split()
    assert fields[0] == "1700000000.123456789"
    assert [float(v) for v in fields[1:4]] == [1.5, -2.0, 0.0]
    q = [float(v) for v in fields[4:]]
    assert q[:2] == [0.0, 0.0]
    assert np.allclose(q[2:], [math.sin(math.pi / 4), math.cos(math.pi / 4)], atol=1e-15)
    np.testing.assert_allclose(np.loadtxt(path, ndmin=2), [[1.700000000123456789e9, 1.5, -2.0, 0, 0, 0, *q[2:]]])


def test_read_yaw_of_3d_quaternions_and_skips_comments(tmp_path: Path) -> None:
    # rotation of 0.3 rad about z, not normalized (scaled by 2); then a 180° turn about x (yaw 0)
    qz, qw = 2 * math.sin(0.15), 2 * math.cos(0.15)
    path = tmp_path / "t.tum"
    path.write_text(f"# header\n\n  # indented comment\n0.5 1 2 3 0 0 {qz} {qw}\n1.0 0 0 0 1 0 0 0\n")
    back = read_tum(path)
    assert back.stamp_ns.tolist() == [500_000_000, 1_000_000_000]
    assert back.x.tolist() == [1.0, 0.0]
    assert np.allclose(back.yaw, [0.3, 0.0])
    csv = tmp_path / "t.csv"  # the same poses comma-separated, as some tools export them
    csv.write_text(f"#timestamp,x,y,z,qx,qy,qz,qw\n0.5,1,2,3,0,0,{qz},{qw}\n1.0, 0, 0, 0, 1, 0, 0, 0\n")
    again = read_tum(csv)
    assert again.stamp_ns.tolist() == back.stamp_ns.tolist() and np.allclose(again.yaw, back.yaw)


@pytest.mark.parametrize(
    ("line", "message"),
    [("1.0 1 2 3 0 0 0", "expected 8 fields"), ("abc 1 2 3 0 0 0 1", "timestamp 'abc' is not a number"),
     ("1.0 x 2 3 0 0 0 1", "could not convert"), ("1.0 1 2 3 0 0 0 0", "zero norm"),
     ("nan 1 2 3 0 0 0 1", "not finite"), ("1.0 inf 2 3 0 0 0 1", "non-finite"),
     ("1e20 1 2 3 0 0 0 1", "int64"),
     ("1700000000000000000 1 2 3 0 0 0 1", "looks like nanoseconds"),
     ("1700000000000000 1 2 3 0 0 0 1", "looks like microseconds"),
     ("1700000000000 1 2 3 0 0 0 1", "looks like milliseconds")],
)
def test_bad_line_names_file_and_line_number(tmp_path: Path, line: str, message: str) -> None:
    path = tmp_path / "bad.tum"
    path.write_text(f"# header\n0.0 0 0 0 0 0 0 1\n{line}\n")
    with pytest.raises(InputDataError, match=message) as info:
        read_tum(path)
    assert info.value.path == str(path)
    assert "line 3" in str(info.value)


def test_stamps_going_backwards_are_refused_with_the_file_and_pose(tmp_path: Path) -> None:
    path = tmp_path / "shuffled.tum"
    path.write_text("0.0 0 0 0 0 0 0 1\n0.2 1 0 0 0 0 0 1\n0.1 2 0 0 0 0 0 1\n0.1 2 0 0 0 0 0 1\n")
    with pytest.raises(InputDataError, match=r"backwards 1 time\(s\), first after the 2\. pose") as info:
        read_tum(path)
    assert info.value.path == str(path)


def test_a_trajectory_that_leaves_the_plane_is_read_in_it_with_a_warning(tmp_path: Path,
                                                                         caplog: pytest.LogCaptureFixture) -> None:
    tilt = math.radians(10.0)  # a 10° pitch on the second pose, and a 0.2 m climb
    path = tmp_path / "handheld.tum"
    path.write_text(f"0.0 0 0 0 0 0 0 1\n1.0 1 0 0.2 0 {math.sin(tilt / 2)} 0 {math.cos(tilt / 2)}\n")
    with caplog.at_level(logging.WARNING):
        back = read_tum(path)
    assert back.x.tolist() == [0.0, 1.0]
    assert "not planar (z ranges over 0.200 m, tilt up to 10.0°)" in caplog.text
    caplog.clear()
    flat = tmp_path / "flat.tum"
    flat.write_text("0.0 0 0 0.01 0 0 0 1\n1.0 1 0 0.02 0 0 0.3 0.95\n")
    with caplog.at_level(logging.WARNING):
        read_tum(flat)
    assert caplog.text == ""


def test_missing_file_is_input_data_error(tmp_path: Path) -> None:
    with pytest.raises(InputDataError) as info:
        read_tum(tmp_path / "none.tum")
    assert info.value.path == str(tmp_path / "none.tum")


@pytest.mark.parametrize(
    ("stamp", "x"),
    [(np.array([0.5]), [0.0]), (np.array([1, 2]), [0.0]), (np.array([1]), [np.nan])],
)
def test_write_rejects_bad_arrays_and_leaves_no_file(tmp_path: Path, stamp: np.ndarray, x: list[float]) -> None:
    with pytest.raises(ValueError):
        write_tum(tmp_path / "t.tum", stamp, x, np.zeros(len(x)), np.zeros(len(x)))
    assert list(tmp_path.iterdir()) == []
