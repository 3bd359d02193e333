"""The six Parquet tables of DESIGN.md (Outputs): their exact schemas, a checked writer and reader.

Columns are SI units in the map frame; angles are radians that the producing stage wraps to (−π, π]
(this module stores them as given and does not rewrap). Unlabelled floats are float64.

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

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_path

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
    ("doors", "source"): frozenset({"grid", "em"}),
    ("trajectory", "method"): frozenset({"mcl", "rbpf", "odom", "reference"}),
    ("door_poses", "handle_side"): frozenset({"left", "right", "none"}),
    ("door_poses", "fit"): frozenset({"naive", "lsq", "ransac"}),
}


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


def _schema_diff(found: pa.Schema, expected: pa.Schema) -> str:
    """A short description of how ``found`` differs from ``expected``."""
    missing = [n for n in expected.names if n not in found.names]
    extra = [n for n in found.names if n not in expected.names]
    types = [
        f"{f.name} is {found.field(f.name).type}, expected {f.type}"
        for f in expected
        if f.name in found.names and found.field(f.name).type != f.type
    ]
    parts = []
    if missing:
        parts.append(f"missing columns {missing}")
    if extra:
        parts.append(f"unexpected columns {extra}")
    parts += types
    if not parts:
        parts = [f"column order {found.names}, expected {expected.names}"]
    return "; ".join(parts)


def read_table(name: str, path: Path) -> pa.Table:
    """Read the Parquet file ``path`` and check that its schema is exactly table ``name``'s contract.

    Raises:
        ValueError: ``name`` is not one of :data:`TABLES`.
        InputDataError: The file is missing, not Parquet, or its schema differs (names the file).
    """
    expected = schema_of(name)
    path = Path(path)
    if not path.is_file():
        raise InputDataError(f"{name} table: no such file", path=path)
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as err:
        raise InputDataError(f"{name} table: not a readable Parquet file: {err}", path=path) from err
    if not table.schema.equals(expected, check_metadata=False):
        diff = _schema_diff(table.schema, expected)
        raise InputDataError(f"not a doorbatch {name} table: {diff}", path=path)
    return table.replace_schema_metadata(None)
