"""The six Parquet tables of DESIGN.md (Outputs): their exact schemas, a checked writer and reader.

Columns are SI units in the map frame; angles are radians that the producing stage wraps to (−π, π]
(this module stores them as given and does not rewrap). Unlabelled floats are float64. The writer enforces the
exact schema; the reader takes what other tools write of the same data (columns by name, in any order, extra
columns left out, lossless casts: :func:`read_table`) and refuses bad values (:mod:`doorbatch.io.table_values`).

| table | columns |
| --- | --- |
| doors | door_id int32, hinge_x, hinge_y, length, closed_yaw, angle_min, angle_max, n_observations int32, |
|       | source string (grid, em), moved bool |
| walls | wall_id int32, segment_id int32, x0, y0, x1, y1, normal_x, normal_y, offset |
| trajectory | log, method string (mcl, rbpf, odom, reference), stamp_ns int64, x, y, yaw, cov_xx, cov_xy, |
|            | cov_yy, cov_yaw, n_particles int32, neff |
| door_states | log, method string, stamp_ns int64, door_id int32, angle, angle_std, observed bool |
| door_poses | log string, stamp_ns int64, door_id int32, center_x, center_y, yaw, width, handle_side string |
|            | (left, right, none), fit string (naive, lsq, ransac), goal_x, goal_y, goal_yaw, frame string |
| metrics | run, log, method, metric string, value float64, unit string, params string (JSON) |
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_path
from doorbatch.io.table_values import DOOR_SOURCES, check_values, describe_row

F64 = pa.float64()
I32 = pa.int32()
I64 = pa.int64()
STR = pa.string()
BOOL = pa.bool_()


def _schema(*columns: tuple[str, pa.DataType]) -> pa.Schema:
    return pa.schema([pa.field(name, dtype) for name, dtype in columns])


def _floats(*names: str) -> list[tuple[str, pa.DataType]]:
    return [(name, F64) for name in names]


DOORS = _schema(
    ("door_id", I32),
    *_floats("hinge_x", "hinge_y", "length", "closed_yaw", "angle_min", "angle_max"),
    ("n_observations", I32), ("source", STR), ("moved", BOOL),
)
WALLS = _schema(
    ("wall_id", I32), ("segment_id", I32),
    *_floats("x0", "y0", "x1", "y1", "normal_x", "normal_y", "offset"),
)
TRAJECTORY = _schema(
    ("log", STR), ("method", STR), ("stamp_ns", I64),
    *_floats("x", "y", "yaw", "cov_xx", "cov_xy", "cov_yy", "cov_yaw"),
    ("n_particles", I32), ("neff", F64),
)
DOOR_STATES = _schema(
    ("log", STR), ("method", STR), ("stamp_ns", I64), ("door_id", I32),
    *_floats("angle", "angle_std"), ("observed", BOOL),
)
DOOR_POSES = _schema(
    ("log", STR), ("stamp_ns", I64), ("door_id", I32),
    *_floats("center_x", "center_y", "yaw", "width"),
    ("handle_side", STR), ("fit", STR),
    *_floats("goal_x", "goal_y", "goal_yaw"), ("frame", STR),
)
METRICS = _schema(
    ("run", STR), ("log", STR), ("method", STR), ("metric", STR), ("value", F64), ("unit", STR),
    ("params", STR),
)

TABLES: dict[str, pa.Schema] = {
    "doors": DOORS,
    "walls": WALLS,
    "trajectory": TRAJECTORY,
    "door_states": DOOR_STATES,
    "door_poses": DOOR_POSES,
    "metrics": METRICS,
}

# String columns whose values DESIGN.md enumerates: checked on write.
ALLOWED_VALUES: dict[tuple[str, str], frozenset[str]] = {
    ("doors", "source"): DOOR_SOURCES,
    ("trajectory", "method"): frozenset({"mcl", "rbpf", "odom", "reference"}),
    ("door_poses", "handle_side"): frozenset({"left", "right", "none"}),
    ("door_poses", "fit"): frozenset({"naive", "lsq", "ransac"}),
}


# Tables whose nulls read_table keeps as they are: doorbatch only copies metrics, never computes with them.
NULLS_KEPT = frozenset({"metrics"})


def schema_of(name: str) -> pa.Schema:
    """The contract schema of table ``name``.

    Raises:
        ValueError: ``name`` is not one of :data:`TABLES`.
    """
    try:
        return TABLES[name]
    except KeyError:
        raise ValueError(f"unknown table {name!r} (tables: {', '.join(TABLES)})") from None


def _same_kind(src: pa.DataType, dst: pa.DataType) -> bool:
    """Whether values of type ``src`` may be cast to ``dst``: strings to strings, bools to bools, numbers
    to numbers (an all-null or empty column fits anything)."""
    if pa.types.is_null(src):
        return True
    if pa.types.is_string(dst):
        return bool(pa.types.is_string(src) or pa.types.is_large_string(src))
    if pa.types.is_boolean(dst):
        return bool(pa.types.is_boolean(src))
    return bool(pa.types.is_integer(src) or pa.types.is_floating(src))


def _column(name: str, field: pa.Field, values: Any) -> pa.Array:
    """``values`` as an Arrow array of the field's type, cast safely (no truncation or overflow)."""
    where = f"table {name!r}, column {field.name!r}"
    try:
        array = values if isinstance(values, pa.Array | pa.ChunkedArray) else pa.array(values)
        if isinstance(array, pa.ChunkedArray):
            array = array.combine_chunks()
    except (pa.ArrowException, TypeError, ValueError) as err:
        raise ValueError(f"{where}: not an array: {err}") from err
    if not _same_kind(array.type, field.type):
        raise ValueError(f"{where}: values of type {array.type} cannot be stored as {field.type}")
    try:
        return array.cast(field.type, safe=True)
    except (pa.ArrowException, TypeError, ValueError) as err:
        raise ValueError(f"{where}: cannot store as {field.type}: {err}") from err


def _check_values(name: str, table: pa.Table) -> None:
    """Reject values outside the enumerations of :data:`ALLOWED_VALUES`."""
    for (table_name, column), allowed in ALLOWED_VALUES.items():
        if table_name != name:
            continue
        present = {v for v in table.column(column).unique().to_pylist() if v is not None}
        bad = sorted(present - allowed)
        if bad:
            raise ValueError(f"table {name!r}, column {column!r}: values {bad} not in {sorted(allowed)}")


def build_table(name: str, columns: Mapping[str, Any]) -> pa.Table:
    """An Arrow table of table ``name`` with exactly its contract schema, from array-likes.

    Args:
        name: One of :data:`TABLES`.
        columns: Column name → NumPy array, list, or Arrow array; all of one length.

    Raises:
        ValueError: Unknown table, a missing or extra column, lengths differ, a value that does not fit
            the column type (e.g. 1.5 into int32, 2**40 into int32), or a string outside its enumeration.
    """
    schema = schema_of(name)
    missing = [n for n in schema.names if n not in columns]
    extra = [n for n in columns if n not in schema.names]
    if missing or extra:
        raise ValueError(f"table {name!r}: missing columns {missing}, unexpected columns {extra}")
    arrays = [_column(name, field, columns[field.name]) for field in schema]
    lengths = {field.name: len(a) for field, a in zip(schema, arrays, strict=True)}
    if len(set(lengths.values())) > 1:
        raise ValueError(f"table {name!r}: columns differ in length: {lengths}")
    table = pa.Table.from_arrays(arrays, schema=schema)
    _check_values(name, table)
    return table


def write_table(name: str, columns: Mapping[str, Any] | pa.Table, dest: Path) -> None:
    """Write table ``name`` to the Parquet file ``dest`` atomically, enforcing its contract schema.

    Args:
        name: One of :data:`TABLES`.
        columns: Column name → array-like, or an Arrow table with those columns.
        dest: The ``.parquet`` file to write (its folder is created if missing).

    Raises:
        ValueError: See :func:`build_table`.
        OSError: The file cannot be written.
    """
    if isinstance(columns, pa.Table):
        columns = {n: columns.column(n) for n in columns.column_names}
    table = build_table(name, columns)
    with atomic_path(dest) as tmp:
        pq.write_table(table, tmp)


def _plain(column: pa.ChunkedArray) -> pa.ChunkedArray:
    """A dictionary-encoded column (a pandas categorical, say) as its values; other columns unchanged."""
    if pa.types.is_dictionary(column.type):
        return column.cast(column.type.value_type)
    return column


def _castable(src: pa.DataType, dst: pa.DataType) -> bool:
    """Whether a column of type ``src`` may hold the values of a ``dst`` column: strings of any layout for a
    string, integers for an integer (their values are checked by the cast), floats or integers for a float64,
    bools for a bool (an all-null or empty column fits anything; its nulls are judged after)."""
    if pa.types.is_null(src):
        return True
    if pa.types.is_string(dst):
        return bool(pa.types.is_string(src) or pa.types.is_large_string(src) or pa.types.is_string_view(src))
    if pa.types.is_integer(dst):
        return bool(pa.types.is_integer(src))
    if pa.types.is_floating(dst):
        return bool(pa.types.is_floating(src) or pa.types.is_integer(src))
    return bool(pa.types.is_boolean(dst) and pa.types.is_boolean(src))


def _conform_column(name: str, field: pa.Field, column: pa.ChunkedArray, path: Path) -> pa.ChunkedArray:
    """``column`` of the file as the contract's ``field``, losing nothing, or InputDataError."""
    where = f"{name} table: column {field.name!r}"
    column = _plain(column)
    src = column.type
    # A 0/1 integer column for a bool one is taken: tools without a bool type (CSV converters, R, an
    # astype(int) in pandas) write flags so, and 0/1 → False/True loses nothing; any other value is refused.
    if pa.types.is_boolean(field.type) and pa.types.is_integer(src):
        outside = pc.or_(pc.less(column, pa.scalar(0, src)), pc.greater(column, pa.scalar(1, src)))
        bad = int(pc.index(outside, True).as_py())
        if bad >= 0:
            raise InputDataError(f"{where} is {src} with value {column[bad].as_py()} in row {bad}, expected bool "
                                 "(or integers 0 and 1)", path=path)
        return pc.not_equal(column, pa.scalar(0, src))
    if not _castable(src, field.type):
        raise InputDataError(f"{where} is {src}, expected {field.type}", path=path)
    try:
        return column.cast(field.type, safe=True)
    except (pa.ArrowException, TypeError, ValueError) as err:
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise InputDataError(f"{where} is {src} with a value that {field.type} cannot hold exactly ({reason}), "
                             f"expected {field.type}", path=path) from err


def _settle_nulls(name: str, table: pa.Table, path: Path) -> pa.Table:
    """Nulls of ``table`` (with the contract's schema) as doorbatch reads them: NaN in a float64 column, refused
    in any other column, except in metrics (copied as they are)."""
    if name in NULLS_KEPT:
        return table
    for i, field in enumerate(table.schema):
        column = table.column(i)
        if column.null_count == 0:
            continue
        if pa.types.is_floating(field.type):
            # pandas writes NaN as null (pd.read_parquet(p).to_parquet(p) turns every NaN of doorbatch's into one)
            table = table.set_column(i, field, pc.fill_null(column, float("nan")))
            continue
        row = int(pc.index(pc.is_null(column), True).as_py())
        raise InputDataError(f"{name} table, {describe_row(name, table, row)}: column {field.name!r} is null, "
                             f"expected a value ({field.type}) in every row", path=path)
    return table


def _pandas_index_hint(schema: pa.Schema, missing: list[str]) -> str:
    """A hint when pandas kept a missing column as its index in metadata only (a RangeIndex), else ''."""
    try:
        pandas = json.loads((schema.metadata or {}).get(b"pandas", b"{}"))
        names = {i.get("name") for i in pandas.get("index_columns", []) if isinstance(i, dict)}
    except (ValueError, AttributeError):
        return ""
    kept = [n for n in missing if n in names]
    return f"; pandas stored {kept} as its index only: write with df.reset_index()" if kept else ""


def _conform(name: str, found: pa.Table, path: Path) -> pa.Table:
    """``found`` with exactly table ``name``'s contract columns, in its order and types (see :func:`read_table`)."""
    expected = schema_of(name)
    missing = [n for n in expected.names if n not in found.column_names]
    if missing:
        raise InputDataError(f"{name} table: missing columns {missing} (the file has {found.column_names})"
                             f"{_pandas_index_hint(found.schema, missing)}", path=path)
    twice = [n for n in expected.names if found.column_names.count(n) > 1]
    if twice:
        raise InputDataError(f"{name} table: columns {twice} appear more than once", path=path)
    columns = [_conform_column(name, f, found.column(f.name), path) for f in expected]
    return _settle_nulls(name, pa.Table.from_arrays(columns, schema=expected), path)


def read_table(name: str, path: Path) -> pa.Table:
    """Read table ``name`` from the Parquet file ``path`` as its contract schema, and check its values.

    Files other tools write are taken when they hold the contract's data: columns are matched by name, in any
    order; columns the contract lacks are left out; each column is cast to its contract type when that loses
    nothing (string, large_string or string_view to string; any integer type to int32/int64 when every value
    fits; float16/float32, and integers that float64 holds exactly, to float64; bool, or integers all 0 or 1,
    to bool; a dictionary-encoded column by its values). A null in a float64 column reads as NaN (pandas writes
    NaN so); a null anywhere else is refused (metrics keeps its nulls). Then
    :func:`~doorbatch.io.table_values.check_values` refuses values doorbatch cannot use.

    Returns:
        A table with exactly the contract's columns, in its order and types, without schema metadata.

    Raises:
        ValueError: ``name`` is not one of :data:`TABLES`.
        InputDataError: The file is missing or not Parquet; a contract column is missing, of another kind
            (double for int64, string for int32), holds a value its type cannot (2**40 for int32), or a null
            where one is refused; or a value check fails. One line naming the file and the column.
    """
    expected = schema_of(name)
    path = Path(path)
    if not path.is_file():
        raise InputDataError(f"{name} table: no such file", path=path)
    try:
        names = pq.read_schema(path).names
        table = pq.read_table(path, columns=[n for n in names if n in expected.names])
    except (OSError, pa.ArrowException) as err:
        raise InputDataError(f"{name} table: not a readable Parquet file: {err}", path=path) from err
    table = _conform(name, table, path)
    check_values(name, table, path)
    return table
