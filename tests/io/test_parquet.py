"""Parquet tables: exact contract schemas, safe casts, rejection of mismatching files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

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
        elif column == "length":
            columns[column] = np.linspace(0.5, 1.25, n)  # a leaf's length is > 0 (read_table checks)
        else:
            columns[column] = np.linspace(-1.0, 2.5, n)  # exact in float32 too
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
    with pytest.raises(InputDataError, match="'stamp_ns' is double, expected int64") as info:
        read_table("trajectory", tmp_path / "trajectory.parquet")
    assert info.value.path == str(tmp_path / "trajectory.parquet")


def test_read_rejects_a_missing_column(tmp_path: Path) -> None:
    table = build_table("walls", sample_columns("walls"))
    pq.write_table(table.drop_columns(["offset"]), tmp_path / "a.parquet")
    with pytest.raises(InputDataError, match="missing columns \\['offset'\\]") as info:
        read_table("walls", tmp_path / "a.parquet")
    assert str(tmp_path / "a.parquet") in str(info.value)


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


# --- reading what other tools write: columns by name, lossless casts, extra columns left out ---------------


def written(name: str, tmp_path: Path, n: int = 3) -> tuple[pa.Table, Path]:
    """Table ``name`` as doorbatch writes it (NaN where the writers put NaN), and its file."""
    columns = sample_columns(name, n)
    nan_at = np.arange(n) == 1
    for column in {"door_states": ("angle", "angle_std"), "trajectory": ("cov_xy", "neff"),
                   "door_poses": ("goal_x",), "metrics": ("value",)}.get(name, ()):
        columns[column] = np.where(nan_at, np.nan, columns[column])
    if name == "door_states":
        columns["observed"] = ~nan_at  # an unobserved door: NaN angle and std
    path = tmp_path / f"{name}.parquet"
    write_table(name, columns, path)
    return pq.read_table(path), path


def assert_same_table(got: pa.Table, want: pa.Table) -> None:
    """Same schema (metadata aside) and values, NaN equal to NaN."""
    assert got.schema.equals(want.schema, check_metadata=False), f"{got.schema} != {want.schema}"
    assert got.schema.metadata is None
    for field in want.schema:
        a, b = got.column(field.name), want.column(field.name)
        if pa.types.is_floating(field.type):
            np.testing.assert_array_equal(a.to_numpy(), b.to_numpy(), err_msg=field.name)
        else:
            assert a.to_pylist() == b.to_pylist(), field.name


@pytest.mark.parametrize("n", [3, 0])
@pytest.mark.parametrize("name", sorted(set(EXPECTED_COLUMNS) - {"walls"}))  # walls: no string, no NaN to change
def test_pandas_round_trip_reads_back_equal(name: str, n: int, tmp_path: Path) -> None:
    pd = pytest.importorskip("pandas")
    want, path = written(name, tmp_path, n)
    pd.read_parquet(path).to_parquet(path)  # pandas 3: large_string, NaN as null, pandas metadata
    assert_same_table(read_table(name, path), want)


def _as(table: pa.Table, change: Any) -> pa.Table:
    """``table`` with each column's type mapped by ``change(field) -> type``."""
    return pa.Table.from_arrays([table.column(f.name).cast(change(f)) for f in table.schema],
                                names=table.column_names)


VARIANTS = {
    "int64": lambda t: _as(t, lambda f: pa.int64() if f.type == pa.int32() else f.type),
    "unsigned": lambda t: _as(t, lambda f: pa.uint64() if pa.types.is_integer(f.type) else f.type),
    "float32": lambda t: _as(t, lambda f: pa.float32() if f.type == pa.float64() else f.type),
    "float16": lambda t: _as(t, lambda f: pa.float16() if f.type == pa.float64() else f.type),
    "large_string": lambda t: _as(t, lambda f: pa.large_string() if f.type == pa.string() else f.type),
    "categorical": lambda t: _as(t, lambda f: pa.dictionary(pa.int32(), f.type) if f.type == pa.string() else f.type),
    "reordered": lambda t: t.select(list(reversed(t.column_names))),
    "extra_columns": lambda t: t.append_column("note", pa.array(["hand"] * len(t))).add_column(
        0, "__index_level_0__", pa.array(range(len(t)), pa.int64())),
}


CHANGED = [(name, variant) for name in sorted(EXPECTED_COLUMNS) for variant in sorted(VARIANTS)
           if not VARIANTS[variant](build_table(name, sample_columns(name))).schema.equals(TABLES[name])]


@pytest.mark.parametrize(("name", "variant"), CHANGED)  # those where the variant changes the schema
def test_lossless_variants_read_back_equal(name: str, variant: str, tmp_path: Path) -> None:
    want, path = written(name, tmp_path)
    pq.write_table(VARIANTS[variant](want), path)
    assert_same_table(read_table(name, path), want)


WIDER = {  # types another tool may write for a contract type (each holds the values drawn below exactly)
    pa.int32(): [pa.int32(), pa.int64(), pa.int16(), pa.uint32(), pa.uint8()],
    pa.int64(): [pa.int64(), pa.uint64(), pa.int32()],
    pa.float64(): [pa.float64(), pa.float32(), pa.float16(), pa.int64()],
    pa.string(): [pa.string(), pa.large_string(), pa.dictionary(pa.int8(), pa.string())],
    pa.bool_(): [pa.bool_(), pa.int8()],
}


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), name=st.sampled_from(sorted(EXPECTED_COLUMNS)))
def test_any_order_and_lossless_types_read_back_equal(data: st.DataObject, name: str, tmp_path: Path) -> None:
    columns = sample_columns(name, 4)
    for column in columns:  # small integral floats: every type of WIDER holds them
        if TABLES[name].field(column).type == pa.float64():
            columns[column] = np.array([1.0, 2.0, 3.0, 0.0 if column != "length" else 1.0])  # |angle| ≤ π
    want = build_table(name, columns)
    order = data.draw(st.permutations(want.column_names))
    types = {f.name: data.draw(st.sampled_from(WIDER[f.type])) for f in want.schema}
    other = pa.Table.from_arrays([want.column(c).cast(types[c]) for c in order], names=order)
    pq.write_table(other, tmp_path / "t.parquet")
    assert_same_table(read_table(name, tmp_path / "t.parquet"), want)


def test_float_for_an_integer_column_is_refused(tmp_path: Path) -> None:
    table = build_table("doors", sample_columns("doors"))
    pq.write_table(table.set_column(0, "door_id", pa.array([0.0, 1.0, 2.0])), tmp_path / "d.parquet")
    with pytest.raises(InputDataError, match="'door_id' is double, expected int32"):
        read_table("doors", tmp_path / "d.parquet")


def test_lossy_integer_cast_is_refused(tmp_path: Path) -> None:
    table = build_table("doors", sample_columns("doors"))
    pq.write_table(table.set_column(0, "door_id", pa.array([0, 1, 2**40], pa.int64())), tmp_path / "d.parquet")
    with pytest.raises(InputDataError, match=r"'door_id' is int64 with a value that int32 cannot hold.*1099511627776"):
        read_table("doors", tmp_path / "d.parquet")


def test_integers_are_read_as_floats_only_when_exact(tmp_path: Path) -> None:
    table = build_table("doors", sample_columns("doors"))
    i = table.schema.get_field_index("hinge_x")
    pq.write_table(table.set_column(i, "hinge_x", pa.array([1, 2, 3], pa.int64())), tmp_path / "a.parquet")
    assert read_table("doors", tmp_path / "a.parquet").column("hinge_x").to_pylist() == [1.0, 2.0, 3.0]
    pq.write_table(table.set_column(i, "hinge_x", pa.array([1, 2, 2**53 + 1], pa.int64())), tmp_path / "b.parquet")
    with pytest.raises(InputDataError, match=r"'hinge_x' is int64 .*9007199254740993"):
        read_table("doors", tmp_path / "b.parquet")


def test_integer_moved_is_read_when_all_zero_or_one(tmp_path: Path) -> None:
    table = build_table("doors", sample_columns("doors"))
    i = table.schema.get_field_index("moved")
    pq.write_table(table.set_column(i, "moved", pa.array([1, 0, 1], pa.int64())), tmp_path / "a.parquet")
    assert read_table("doors", tmp_path / "a.parquet").column("moved").to_pylist() == [True, False, True]
    pq.write_table(table.set_column(i, "moved", pa.array([1, 0, 2], pa.int64())), tmp_path / "b.parquet")
    with pytest.raises(InputDataError, match="'moved' is int64 with value 2 in row 2, expected bool"):
        read_table("doors", tmp_path / "b.parquet")


def test_string_for_an_integer_column_is_refused(tmp_path: Path) -> None:
    table = build_table("doors", sample_columns("doors"))
    pq.write_table(table.set_column(0, "door_id", pa.array(["0", "1", "2"])), tmp_path / "d.parquet")
    with pytest.raises(InputDataError, match="'door_id' is string, expected int32"):
        read_table("doors", tmp_path / "d.parquet")


@pytest.mark.parametrize(("name", "column", "where"), [
    ("doors", "n_observations", "door_id 8 \\(row 1\\)"),
    ("doors", "moved", "door_id 8 \\(row 1\\)"),
    ("trajectory", "log", "row 1 \\(method 'rbpf', stamp_ns 8\\)"),
    ("door_states", "door_id", "row 1 \\(stamp_ns 8\\)"),
    ("walls", "segment_id", "row 1"),
])
def test_null_outside_float_columns_is_refused(name: str, column: str, where: str, tmp_path: Path) -> None:
    table = build_table(name, sample_columns(name))
    i = table.schema.get_field_index(column)
    values = table.column(column).to_pylist()
    values[1] = None
    pq.write_table(table.set_column(i, column, pa.array(values, table.schema.field(column).type)), tmp_path / "t.pq")
    with pytest.raises(InputDataError, match=f"{name} table, {where}: column '{column}' is null") as info:
        read_table(name, tmp_path / "t.pq")
    assert info.value.path == str(tmp_path / "t.pq")


def test_null_in_a_float_column_reads_as_nan(tmp_path: Path) -> None:
    table = build_table("door_states", sample_columns("door_states"))
    i = table.schema.get_field_index("angle_std")
    pq.write_table(table.set_column(i, "angle_std", pa.array([0.1, None, 0.3])), tmp_path / "s.parquet")
    got = read_table("door_states", tmp_path / "s.parquet").column("angle_std")
    assert got.null_count == 0
    np.testing.assert_array_equal(got.to_numpy(), [0.1, np.nan, 0.3])


def test_a_column_pandas_kept_as_its_index_is_named(tmp_path: Path) -> None:
    pytest.importorskip("pandas")
    columns = sample_columns("doors")
    columns["door_id"] = np.array([3, 9, 5])
    want = build_table("doors", columns)
    path = tmp_path / "doors.parquet"
    want.to_pandas().set_index("door_id").to_parquet(path)  # stored as a column
    assert_same_table(read_table("doors", path), want)
    want.to_pandas().assign(door_id=[0, 1, 2]).set_index("door_id").to_parquet(path)  # a RangeIndex: metadata only
    with pytest.raises(InputDataError, match=r"missing columns \['door_id'\].*pandas stored \['door_id'\] as its "
                       r"index only: write with df.reset_index\(\)"):
        read_table("doors", path)
