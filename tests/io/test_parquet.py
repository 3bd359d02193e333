"""Parquet tables: exact contract schemas, safe casts, rejection of mismatching files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from doorbatch.errors import InputDataError
from doorbatch.io.parquet import TABLES, build_table, read_table, write_table

EXPECTED_COLUMNS = {
    "doors": "door_id:int32 hinge_x hinge_y length closed_yaw angle_min angle_max n_observations:int32 "
    "source:string moved:bool",
    "walls": "wall_id:int32 segment_id:int32 x0 y0 x1 y1 normal_x normal_y offset",
    "trajectory": "log:string method:string stamp_ns:int64 x y yaw cov_xx cov_xy cov_yy cov_yaw "
    "n_particles:int32 neff",
    "door_states": "log:string method:string stamp_ns:int64 door_id:int32 angle angle_std observed:bool",
    "door_poses": "log:string stamp_ns:int64 door_id:int32 center_x center_y yaw width handle_side:string "
    "fit:string goal_x goal_y goal_yaw frame:string",
    "metrics": "run:string log:string method:string metric:string value unit:string params:string",
}

SAMPLE_STRINGS = {"source": "em", "method": "rbpf", "handle_side": "left", "fit": "ransac"}


def _spec(text: str) -> list[tuple[str, str]]:
    """``name:type`` items (no type: float64) as (name, Arrow type alias) pairs."""
    pairs = [item.partition(":") for item in text.split()]
    return [(column, kind or "double") for column, _, kind in pairs]


def sample_columns(name: str, n: int = 3) -> dict[str, Any]:
    """Valid columns of table ``name`` with ``n`` rows, NumPy for numbers, lists for strings."""
    columns: dict[str, Any] = {}
    for column, kind in _spec(EXPECTED_COLUMNS[name]):
        if kind == "string":
            columns[column] = [SAMPLE_STRINGS.get(column, f"{column}{i}") for i in range(n)]
        elif kind == "bool":
            columns[column] = np.arange(n) % 2 == 0
        elif kind.startswith("int"):
            columns[column] = np.arange(n, dtype=np.int64) + 7
        else:
            columns[column] = np.linspace(-1.0, 2.5, n)
    return columns


def test_registry_holds_exactly_the_six_contract_tables() -> None:
    assert set(TABLES) == set(EXPECTED_COLUMNS)


@pytest.mark.parametrize("name", sorted(EXPECTED_COLUMNS))
def test_schema_matches_design_exactly(name: str) -> None:
    expected = [(column, pa.type_for_alias(kind)) for column, kind in _spec(EXPECTED_COLUMNS[name])]
    assert [(f.name, f.type) for f in TABLES[name]] == expected


@pytest.mark.parametrize("name", sorted(EXPECTED_COLUMNS))
def test_write_read_round_trip(name: str, tmp_path: Path) -> None:
    columns = sample_columns(name)
    path = tmp_path / f"{name}.parquet"
    write_table(name, columns, path)
    table = read_table(name, path)
    assert table.schema.equals(TABLES[name])
    for column, values in columns.items():
        assert table.column(column).to_pylist() == list(np.asarray(values).tolist())
    assert [p.name for p in tmp_path.iterdir()] == [f"{name}.parquet"]


def test_int64_input_is_cast_to_int32_column(tmp_path: Path) -> None:
    columns = sample_columns("walls")
    columns["wall_id"] = np.array([1, 2, 3], dtype=np.int64)
    write_table("walls", columns, tmp_path / "walls.parquet")
    assert pq.read_schema(tmp_path / "walls.parquet").field("wall_id").type == pa.int32()


def test_angles_are_stored_as_given_not_rewrapped(tmp_path: Path) -> None:
    columns = sample_columns("door_states")
    columns["angle"] = np.array([4.0, -4.0, np.pi])
    write_table("door_states", columns, tmp_path / "s.parquet")
    assert read_table("door_states", tmp_path / "s.parquet").column("angle").to_pylist() == [4.0, -4.0, np.pi]


def test_missing_column_is_rejected() -> None:
    columns = sample_columns("doors")
    del columns["moved"]
    with pytest.raises(ValueError, match="missing columns \\['moved'\\]"):
        build_table("doors", columns)


def test_extra_column_is_rejected() -> None:
    columns = sample_columns("doors")
    columns["color"] = np.zeros(3)
    with pytest.raises(ValueError, match="unexpected columns \\['color'\\]"):
        build_table("doors", columns)


@pytest.mark.parametrize(
    ("column", "values", "message"),
    [
        ("door_id", np.array([0.5, 1.0, 2.0]), "truncated"),
        ("door_id", np.array([0, 1, 2**40]), "not in range"),
        ("source", [1, 2, 3], "cannot be stored as string"),
        ("moved", np.array([0, 1, 0]), "cannot be stored as bool"),
        ("hinge_x", ["a", "b", "c"], "cannot be stored as double"),
        ("source", ["grid", "em", "lidar"], "not in"),
        ("length", np.zeros(2), "differ in length"),
    ],
)
def test_unsafe_values_are_rejected(column: str, values: Any, message: str) -> None:
    columns = sample_columns("doors")
    columns[column] = values
    with pytest.raises(ValueError, match=message):
        build_table("doors", columns)


def test_unknown_table_name_is_a_value_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="unknown table 'poses'"):
        write_table("poses", {}, tmp_path / "p.parquet")


def test_failed_write_leaves_no_file(tmp_path: Path) -> None:
    columns = sample_columns("metrics")
    columns["value"] = ["x", "y", "z"]
    with pytest.raises(ValueError):
        write_table("metrics", columns, tmp_path / "metrics.parquet")
    assert list(tmp_path.iterdir()) == []


def test_read_rejects_a_file_with_a_different_type(tmp_path: Path) -> None:
    columns = sample_columns("trajectory")
    table = build_table("trajectory", columns)
    bad = table.set_column(2, "stamp_ns", pa.array(columns["stamp_ns"] / 1e9))  # seconds as float
    pq.write_table(bad, tmp_path / "trajectory.parquet")
    with pytest.raises(InputDataError, match="stamp_ns is double, expected int64") as info:
        read_table("trajectory", tmp_path / "trajectory.parquet")
    assert info.value.path == str(tmp_path / "trajectory.parquet")


def test_read_rejects_missing_and_reordered_columns(tmp_path: Path) -> None:
    table = build_table("walls", sample_columns("walls"))
    pq.write_table(table.drop_columns(["offset"]), tmp_path / "a.parquet")
    with pytest.raises(InputDataError, match="missing columns \\['offset'\\]"):
        read_table("walls", tmp_path / "a.parquet")
    pq.write_table(table.select(list(reversed(table.column_names))), tmp_path / "b.parquet")
    with pytest.raises(InputDataError, match="column order"):
        read_table("walls", tmp_path / "b.parquet")


def test_read_names_unreadable_and_missing_files(tmp_path: Path) -> None:
    garbage = tmp_path / "doors.parquet"
    garbage.write_bytes(b"not parquet at all")
    with pytest.raises(InputDataError, match="not a readable Parquet file") as info:
        read_table("doors", garbage)
    assert str(garbage) in str(info.value)
    with pytest.raises(InputDataError, match="no such file"):
        read_table("doors", tmp_path / "missing.parquet")


def test_write_accepts_an_arrow_table_and_empty_tables(tmp_path: Path) -> None:
    table = build_table("metrics", sample_columns("metrics"))
    write_table("metrics", table, tmp_path / "m.parquet")
    assert read_table("metrics", tmp_path / "m.parquet").equals(table)
    write_table("metrics", {c: [] for c in TABLES["metrics"].names}, tmp_path / "empty.parquet")
    assert read_table("metrics", tmp_path / "empty.parquet").num_rows == 0
