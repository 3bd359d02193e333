"""Values read_table refuses (doorbatch.io.table_values): non-finite numbers, degrees for radians, empty ranges,
duplicate doors, stamps that do not advance; and the values doorbatch itself writes, which it takes."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from doorbatch.errors import InputDataError
from doorbatch.io.parquet import TABLES, read_table
from doorbatch.io.table_values import check_values


def doors(**change: Any) -> dict[str, Any]:
    """Three valid doors (ids 4, 5, 6) with ``change`` applied: column → {row: value}."""
    columns: dict[str, Any] = {
        "door_id": [4, 5, 6], "hinge_x": [1.0, 2.0, 3.0], "hinge_y": [0.0, 0.5, -0.5], "length": [0.9, 0.8, 1.0],
        "closed_yaw": [0.0, -np.pi, np.pi], "angle_min": [0.0, -1.5, 0.0], "angle_max": [1.5, 0.0, 0.0],
        "n_observations": [10, 3, 0], "source": ["grid", "em", "em"], "moved": [True, True, False],
    }
    return _changed(columns, change)


def trajectory(**change: Any) -> dict[str, Any]:
    """Two runs of one table: rbpf then mcl on one log, stamps restarting between them; ``change`` as doors."""
    n = 4
    columns: dict[str, Any] = {
        "log": ["a.mcap"] * 2 * n, "method": ["rbpf"] * n + ["mcl"] * n,
        "stamp_ns": [10, 20, 30, 40] * 2, "x": [0.0, 0.1, 0.2, 0.3] * 2, "y": [0.0] * 2 * n,
        "yaw": [3.1, -3.1, np.pi, -np.pi] * 2, "cov_xx": [0.1] * 2 * n, "cov_xy": [np.nan] * 2 * n,
        "cov_yy": [0.1] * 2 * n, "cov_yaw": [0.01] * 2 * n, "n_particles": [100] * 2 * n, "neff": [np.nan] * 2 * n,
    }
    return _changed(columns, change)


def _changed(columns: dict[str, Any], change: dict[str, dict[int, Any]]) -> dict[str, Any]:
    for column, rows in change.items():
        columns[column] = list(columns[column])
        for row, value in rows.items():
            columns[column][row] = value
    return columns


def write(name: str, columns: dict[str, Any], path: Path) -> Path:
    """``columns`` with exactly the contract schema, as another tool would write them (no checks)."""
    pq.write_table(pa.Table.from_pydict(columns, schema=TABLES[name]), path)
    return path


def refusal(name: str, columns: dict[str, Any], path: Path) -> str:
    with pytest.raises(InputDataError) as info:
        read_table(name, write(name, columns, path))
    assert info.value.path == str(path)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_valid_doors_and_trajectory_are_taken(tmp_path: Path) -> None:
    assert read_table("doors", write("doors", doors(), tmp_path / "d.parquet")).num_rows == 3
    assert read_table("trajectory", write("trajectory", trajectory(), tmp_path / "t.parquet")).num_rows == 8


@pytest.mark.parametrize(("column", "value", "expected"), [
    ("hinge_x", np.nan, "'hinge_x' is null or NaN; expected a finite number"),
    ("hinge_y", np.inf, "'hinge_y' is inf; expected a finite number"),
    ("length", -np.inf, "'length' is -inf"),
    ("closed_yaw", np.nan, "'closed_yaw' is null or NaN"),
    ("angle_min", np.nan, "'angle_min' is null or NaN"),
    ("angle_max", np.inf, "'angle_max' is inf"),
    ("hinge_y", None, "'hinge_y' is null or NaN"),
    ("length", 0.0, "'length' is 0 m; a door leaf's length must be > 0"),
    ("length", -0.9, "'length' is -0.9 m"),
    ("angle_max", 100.0, "'angle_max' is 100; angles are radians: 100 looks like degrees"),
    ("angle_min", -7.0, "'angle_min' is -7; angles are radians wrapped to \\(−π, π\\]: -7 wraps to -0.716815, or "
                        "is -0.122173 if it is degrees"),
    ("closed_yaw", 90.0, "'closed_yaw' is 90; angles are radians: 90 looks like degrees"),
    ("closed_yaw", 0.5 + 2 * np.pi, "'closed_yaw' is 6.78319; angles are radians wrapped to \\(−π, π\\]: 6.78319 "
                                    "wraps to 0.5,"),
    ("angle_min", 2.0, "'angle_min' is 2, above angle_max 0; the opening range is angle_min ≤ angle_max"),
    ("door_id", 4, "'door_id' is 4, as in row 0; door ids must be unique"),
    ("door_id", -1, "'door_id' is -1; door ids are ≥ 0"),
    ("source", "manual", "'source' is 'manual'; expected one of em, grid"),
])
def test_bad_door_values_are_refused_naming_door_and_column(column: str, value: Any, expected: str,
                                                            tmp_path: Path) -> None:
    message = refusal("doors", doors(**{column: {1: value}}), tmp_path / "doors.parquet")
    assert "doors table, door_id" in message
    assert str(tmp_path / "doors.parquet") in message
    named = {4: 4, -1: -1}.get(value, 5) if column == "door_id" else 5
    assert f"door_id {named} (row 1): column " in message
    assert re.search(expected, message), message


def test_every_door_value_in_degrees_is_refused_at_the_first_door(tmp_path: Path) -> None:
    columns = doors()
    columns["angle_min"] = list(np.degrees(columns["angle_min"]))
    columns["angle_max"] = list(np.degrees(columns["angle_max"]))
    message = refusal("doors", columns, tmp_path / "doors.parquet")
    assert "door_id 4 (row 0): column 'angle_max' is 85.9437; angles are radians: 85.9437 looks like degrees" in message


@pytest.mark.parametrize(("change", "expected"), [
    ({"x": {5: np.nan}}, "row 5 (log 'a.mcap', method 'mcl', stamp_ns 20): column 'x' is null or NaN"),
    ({"y": {0: np.inf}}, "row 0 (log 'a.mcap', method 'rbpf', stamp_ns 10): column 'y' is inf"),
    ({"yaw": {2: np.nan}}, "column 'yaw' is null or NaN"),
    ({"x": {3: None}}, "row 3 (log 'a.mcap', method 'rbpf', stamp_ns 40): column 'x' is null or NaN"),
    ({"yaw": {1: 179.0}}, "column 'yaw' is 179; angles are radians: 179 looks like degrees"),
    ({"yaw": {1: 4.0}}, "column 'yaw' is 4; angles are radians wrapped to (−π, π]: 4 wraps to -2.28319"),
    ({"stamp_ns": {2: 20}}, "row 2 (log 'a.mcap', method 'rbpf', stamp_ns 20): column 'stamp_ns' is 20, which "
                            "repeats 20 in row 1; stamps must strictly increase within one log and method"),
    ({"stamp_ns": {6: 15}}, "row 6 (log 'a.mcap', method 'mcl', stamp_ns 15): column 'stamp_ns' is 15, which goes "
                            "back from 20 in row 5"),
])
def test_bad_trajectory_values_are_refused_naming_row_and_column(change: dict[str, Any], expected: str,
                                                                 tmp_path: Path) -> None:
    message = refusal("trajectory", trajectory(**change), tmp_path / "trajectory.parquet")
    assert f"{tmp_path / 'trajectory.parquet'}: trajectory table, " in message
    assert expected in message, message


def test_reversed_trajectory_is_refused_at_its_second_row(tmp_path: Path) -> None:
    columns = {c: list(v)[:4][::-1] for c, v in trajectory().items()}
    message = refusal("trajectory", columns, tmp_path / "trajectory.parquet")
    assert "row 1 (log 'a.mcap', method 'rbpf', stamp_ns 30): column 'stamp_ns' is 30, which goes back from 40" \
        in message


def test_interleaved_runs_each_advancing_are_taken(tmp_path: Path) -> None:
    columns = trajectory()
    order = [0, 4, 1, 5, 2, 6, 3, 7]  # rbpf and mcl rows alternate; each advances on its own
    columns = {c: [v[i] for i in order] for c, v in columns.items()}
    columns["log"] = ["a.mcap", "b.mcap"] * 4  # and another log with the same stamps
    assert read_table("trajectory", write("trajectory", columns, tmp_path / "t.parquet")).num_rows == 8


stamps = st.lists(st.integers(0, 6), min_size=0, max_size=30)
groups = st.lists(st.tuples(st.sampled_from(["a", "b"]), st.sampled_from(["rbpf", "mcl"])), min_size=30,
                  max_size=30)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(stamp_list=stamps, group_list=groups)
def test_stamps_are_refused_exactly_when_a_run_does_not_advance(stamp_list: list[int],
                                                                group_list: list[tuple[str, str]]) -> None:
    n = len(stamp_list)
    keys = group_list[:n]
    table = pa.Table.from_pydict({
        "log": [k[0] for k in keys], "method": [k[1] for k in keys], "stamp_ns": stamp_list, "x": [0.0] * n,
        "y": [0.0] * n, "yaw": [0.0] * n, "cov_xx": [0.0] * n, "cov_xy": [0.0] * n, "cov_yy": [0.0] * n,
        "cov_yaw": [0.0] * n, "n_particles": [1] * n, "neff": [1.0] * n}, schema=TABLES["trajectory"])
    last: dict[tuple[str, str], int] = {}
    first_bad = None
    for row, (key, stamp) in enumerate(zip(keys, stamp_list, strict=True)):
        if key in last and stamp <= last[key]:
            first_bad = row
            break
        last[key] = stamp
    if first_bad is None:
        check_values("trajectory", table, Path("t.parquet"))
    else:
        with pytest.raises(InputDataError, match=f"t.parquet: trajectory table, row {first_bad} .*'stamp_ns'"):
            check_values("trajectory", table, Path("t.parquet"))


def door_states(angle: list[float], observed: list[bool]) -> dict[str, Any]:
    n = len(angle)
    return {"log": ["a"] * n, "method": ["rbpf"] * n, "stamp_ns": list(range(n)), "door_id": [3] * n,
            "angle": angle, "angle_std": [np.nan if not o else 0.1 for o in observed], "observed": observed}


def test_door_states_refuse_a_non_finite_observed_angle(tmp_path: Path) -> None:
    columns = door_states([0.5, np.nan, np.inf], [True, False, True])
    message = refusal("door_states", columns, tmp_path / "door_states.parquet")
    assert ("door_states table, row 2 (door_id 3, stamp_ns 2): column 'angle' is inf; expected a finite number "
            "where observed is true") in message


def test_door_states_take_nan_where_not_observed_and_angles_beyond_pi(tmp_path: Path) -> None:
    columns = door_states([4.0, np.nan, -4.0], [True, False, True])
    table = read_table("door_states", write("door_states", columns, tmp_path / "s.parquet"))
    np.testing.assert_array_equal(table.column("angle").to_numpy(), [4.0, np.nan, -4.0])


def test_door_poses_refuse_a_non_finite_center(tmp_path: Path) -> None:
    n = 2
    columns = {"log": ["a"] * n, "stamp_ns": [1, 2], "door_id": [-1, 2], "center_x": [1.0, 2.0],
               "center_y": [0.0, np.nan], "yaw": [0.0, 0.1], "width": [0.9, 0.9], "handle_side": ["left", "none"],
               "fit": ["lsq"] * n, "goal_x": [np.nan] * n, "goal_y": [0.0] * n, "goal_yaw": [0.0] * n,
               "frame": ["map"] * n}
    message = refusal("door_poses", columns, tmp_path / "door_poses.parquet")
    assert "door_poses table, row 1 (door_id 2, stamp_ns 2): column 'center_y' is null or NaN" in message
    columns["center_y"] = [0.0, 1.0]
    assert read_table("door_poses", write("door_poses", columns, tmp_path / "ok.parquet")).num_rows == 2


def test_metrics_values_are_not_checked(tmp_path: Path) -> None:
    columns = {"run": ["r"] * 2, "log": ["a"] * 2, "method": ["amcl"] * 2, "metric": ["m", "n"],
               "value": [np.nan, np.inf], "unit": ["m", None], "params": ["{}", "{}"]}
    table = read_table("metrics", write("metrics", columns, tmp_path / "metrics.parquet"))
    assert table.column("unit").to_pylist() == ["m", None]


def test_a_million_row_trajectory_is_checked(tmp_path: Path) -> None:
    n = 1_000_000
    rng = np.random.default_rng(0)
    table = pa.table({
        "log": pa.array(["a.mcap"] * n).dictionary_encode().cast(pa.string()),
        "method": pa.array(np.where(np.arange(n) % 2 == 0, "rbpf", "mcl")),
        "stamp_ns": np.arange(n, dtype=np.int64) // 2 * 1000,
        **{c: rng.uniform(-3.0, 3.0, n) for c in ("x", "y", "yaw", "cov_xx", "cov_xy", "cov_yy", "cov_yaw")},
        "n_particles": np.full(n, 100, np.int32), "neff": np.full(n, 50.0)}).cast(TABLES["trajectory"])
    check_values("trajectory", table, tmp_path / "t.parquet")
    stamps = table.column("stamp_ns").to_numpy().copy()
    stamps[n - 1] = stamps[n - 3]  # the last mcl row repeats the one before it
    table = table.set_column(2, "stamp_ns", pa.array(stamps))
    with pytest.raises(InputDataError, match=f"row {n - 1} .*which repeats {stamps[n - 3]} in row {n - 3}"):
        check_values("trajectory", table, tmp_path / "t.parquet")


def test_yaw_in_degrees_is_named_as_such_from_the_whole_column(tmp_path: Path) -> None:
    columns = trajectory(yaw={0: 0.0, 1: -6.8, 2: 48.5, 3: 90.0})  # small degrees first: each could be radians
    message = refusal("trajectory", columns, tmp_path / "trajectory.parquet")
    assert "row 1 (log 'a.mcap', method 'rbpf', stamp_ns 20): column 'yaw' is -6.8; angles are radians: -6.8, " \
        "and 90 in another row, look like degrees" in message
