"""Value checks of the Parquet tables that doorbatch reads back (DESIGN.md, Outputs).

:func:`doorbatch.io.parquet.read_table` settles a file's schema, then calls :func:`check_values`, which refuses
values that would give confident wrong results further on, with one line naming the file, the first offending
row (its door_id for doors) and column, and a hint:

| table | refused |
| --- | --- |
| doors | a non-finite hinge_x, hinge_y, length, closed_yaw, angle_min or angle_max; length ≤ 0; an angle outside |
|       | [−π, π] (degrees, or not wrapped); angle_min > angle_max; a door_id < 0 or twice; source not grid or em |
| trajectory | a non-finite x, y or yaw; yaw outside [−π, π]; stamp_ns not strictly increasing within one |
|            | (log, method) |
| door_states | a non-finite angle where observed is true |
| door_poses | a non-finite center_x or center_y |

Left alone because doorbatch writes them: NaN covariances and neff (trajectory), NaN angle and angle_std of a door
not observed (door_states), angles of door_states and door_poses outside (−π, π] (stored as given). walls and
metrics are not checked. Every check is vectorized over the table's columns (tables may have millions of rows).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa
import pyarrow.compute as pc

from doorbatch.errors import InputDataError

DOOR_SOURCES = frozenset({"grid", "em"})
ANGLE_LIMIT_RAD = math.pi + 1e-6  # wrapped to (−π, π]; −π itself is the same angle and accepted

# The columns that name a row in messages, per table (after the row number).
ROW_KEYS: dict[str, tuple[str, ...]] = {
    "trajectory": ("log", "method", "stamp_ns"),
    "door_states": ("door_id", "stamp_ns"),
    "door_poses": ("door_id", "stamp_ns"),
}


def describe_row(name: str, table: pa.Table, row: int) -> str:
    """``row`` of table ``name`` as a message names it: ``door_id 3 (row 0)`` for doors, else ``row 5`` and
    the columns of :data:`ROW_KEYS` present."""
    def value(column: str) -> object:
        return table.column(column)[row].as_py() if column in table.column_names else None

    if name == "doors" and value("door_id") is not None:
        return f"door_id {value('door_id')} (row {row})"
    keys = [f"{c} {value(c)!r}" if isinstance(value(c), str) else f"{c} {value(c)}"
            for c in ROW_KEYS.get(name, ()) if value(c) is not None]
    return f"row {row} ({', '.join(keys)})" if keys else f"row {row}"


def check_values(name: str, table: pa.Table, path: Path) -> None:
    """Refuse values of table ``name`` (with its contract schema, no nulls but NaN) that doorbatch cannot use.

    Args:
        name: One of the tables of :data:`doorbatch.io.parquet.TABLES`.
        table: The table, already with exactly the contract's columns and types.
        path: The file it came from, for the message.

    Raises:
        InputDataError: The first offending value (see the module's table), naming the file, row and column.
    """
    check = _CHECKS.get(name)
    if check is not None:
        check(_Table(name, table, Path(path)))


class _Table:
    """A table being checked, with the file it came from: its float columns as NumPy, and the error to raise."""

    def __init__(self, name: str, table: pa.Table, path: Path) -> None:
        self.name, self.table, self.path = name, table, path

    def floats(self, column: str) -> npt.NDArray[np.float64]:
        return np.asarray(self.table.column(column).to_numpy(), dtype=np.float64)

    def fail(self, row: int, column: str, found: str, expected: str) -> InputDataError:
        return InputDataError(f"{self.name} table, {describe_row(self.name, self.table, row)}: column {column!r} "
                              f"is {found}; {expected}", path=self.path)

    def finite(self, *columns: str, where: npt.NDArray[np.bool_] | None = None, why: str = "") -> None:
        """Each of ``columns`` finite (in the rows ``where``); else the first row with a value that is not."""
        values = {c: self.floats(c) for c in columns}
        hit = self.first_hit({c: ~np.isfinite(v) if where is None else ~np.isfinite(v) & where
                              for c, v in values.items()})
        if hit is not None:
            row, column = hit
            value = values[column][row]
            raise self.fail(row, column, "null or NaN" if np.isnan(value) else str(value),
                            f"expected a finite number{why}")

    def angles(self, *columns: str) -> None:
        """Each of ``columns`` within [−π, π] (+1e-6); a hint says whether it looks like degrees or unwrapped."""
        values = {c: self.floats(c) for c in columns}
        hit = self.first_hit({c: np.abs(v) > ANGLE_LIMIT_RAD for c, v in values.items()})
        if hit is not None:
            row, column = hit
            largest = float(np.max(np.abs(values[column])))
            raise self.fail(row, column, f"{values[column][row]:.6g}", _angle_hint(values[column][row], largest))

    @staticmethod
    def first_hit(masks: dict[str, npt.NDArray[np.bool_]]) -> tuple[int, str] | None:
        """The first row where any of ``masks`` holds, with the first of their columns that holds there."""
        rows = {c: _first(m) for c, m in masks.items()}
        found = [(r, i, c) for i, (c, r) in enumerate(rows.items()) if r is not None]
        if not found:
            return None
        row, _, column = min(found)
        return row, column


def _first(mask: npt.NDArray[np.bool_]) -> int | None:
    """The first index where ``mask`` holds, or None."""
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def _angle_hint(value: float, largest: float) -> str:
    """Why an angle beyond ±π is wrong: with values of its column beyond ±4π the column is surely degrees;
    nearer, it may be either."""
    if abs(value) > 4 * math.pi:
        return f"angles are radians: {value:.6g} looks like degrees"
    if largest > 4 * math.pi:
        return f"angles are radians: {value:.6g}, and {largest:.6g} in another row, look like degrees"
    return (f"angles are radians wrapped to (−π, π]: {value:.6g} wraps to {math.remainder(value, 2 * math.pi):.6g}, "
            f"or is {math.radians(value):.6g} if it is degrees")


def _check_doors(t: _Table) -> None:
    t.finite("hinge_x", "hinge_y", "length", "closed_yaw", "angle_min", "angle_max")
    t.angles("closed_yaw", "angle_min", "angle_max")
    length = t.floats("length")
    row = _first(length <= 0.0)
    if row is not None:
        raise t.fail(row, "length", f"{length[row]:.6g} m", "a door leaf's length must be > 0")
    lo, hi = t.floats("angle_min"), t.floats("angle_max")
    row = _first(lo > hi)
    if row is not None:
        raise t.fail(row, "angle_min", f"{lo[row]:.6g}, above angle_max {hi[row]:.6g}",
                     "the opening range is angle_min ≤ angle_max (swapped?)")
    ids = t.table.column("door_id").to_numpy()
    row = _first(ids < 0)
    if row is not None:  # door_poses' −1 is "no mapped door"
        raise t.fail(row, "door_id", f"{ids[row]}", "door ids are ≥ 0 (door_poses names an unmatched door −1)")
    _, first_rows = np.unique(ids, return_index=True)
    again = np.ones(ids.size, dtype=bool)
    again[first_rows] = False
    row = _first(again)
    if row is not None:
        before = _first(ids == ids[row])
        raise t.fail(row, "door_id", f"{ids[row]}, as in row {before}", "door ids must be unique")
    source = t.table.column("source")
    known = pc.is_in(source, value_set=pa.array(sorted(DOOR_SOURCES))).to_numpy(zero_copy_only=False)
    row = _first(~known)
    if row is not None:
        raise t.fail(row, "source", repr(source[row].as_py()), f"expected one of {', '.join(sorted(DOOR_SOURCES))}")


def _check_trajectory(t: _Table) -> None:
    t.finite("x", "y", "yaw")
    t.angles("yaw")
    stamps = t.table.column("stamp_ns").to_numpy()
    if stamps.size < 2:
        return
    log = pc.dictionary_encode(t.table.column("log")).combine_chunks()
    method = pc.dictionary_encode(t.table.column("method")).combine_chunks()
    group = (log.indices.to_numpy().astype(np.int64) * max(len(method.dictionary), 1)
             + method.indices.to_numpy().astype(np.int64))
    order = np.argsort(group, kind="stable")  # rows of each (log, method) in file order, group after group
    same = group[order][1:] == group[order][:-1]
    back = same & (np.diff(stamps[order]) <= 0)
    if back.any():
        hits = np.flatnonzero(back)
        k = int(hits[np.argmin(order[hits + 1])])  # the offending row that comes first in the file
        row, previous = int(order[k + 1]), int(order[k])
        what = "repeats" if stamps[row] == stamps[previous] else "goes back from"
        raise t.fail(row, "stamp_ns", f"{stamps[row]}, which {what} {stamps[previous]} in row {previous}",
                     "stamps must strictly increase within one log and method")


def _check_door_states(t: _Table) -> None:
    observed = t.table.column("observed").to_numpy()
    t.finite("angle", where=np.asarray(observed, dtype=bool), why=" where observed is true")


def _check_door_poses(t: _Table) -> None:
    t.finite("center_x", "center_y")


_CHECKS: dict[str, Callable[[_Table], None]] = {
    "doors": _check_doors,
    "trajectory": _check_trajectory,
    "door_states": _check_door_states,
    "door_poses": _check_door_poses,
}
