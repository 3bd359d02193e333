"""A CARMEN log with its poses replaced: how a corrected log becomes a raw one for tests and benchmarks.

A raw CARMEN log holds the robot's odometry in every FLASER line twice (the laser pose, and the odometry fields)
and in its ODOM lines; a corrected log holds the corrected poses in all of them (DESIGN.md, Known pitfalls).
:func:`rewrite_carmen_poses` hands the poses of those lines, in file order, to a function (e.g. the simulator's
drift model) and writes the log again with what it returns in every pose field. Lines of other kinds, and every
reading and time stamp, are copied as they are. FLASER laser poses are written equal to the odometry, as a log
whose ``robot_frontlaser_offset`` is zero has them.
"""

from __future__ import annotations

import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.errors import LogReadError
from doorbatch.io.carmen import open_carmen_text

FloatArray = npt.NDArray[np.float64]


def _read_lines(path: Path) -> list[str]:
    try:
        with open_carmen_text(path) as f:
            return f.read().splitlines()
    except (OSError, EOFError, zlib.error) as err:
        raise LogReadError(f"cannot read CARMEN log: {err}", path=path) from err


def rewrite_carmen_poses(source: Path, output: Path, new_poses: Callable[[FloatArray], FloatArray]) -> int:
    """Write ``source`` to ``output`` (plain text) with the poses of its FLASER and ODOM lines replaced.

    ``new_poses`` gets the (N, 3) x, y, θ of those lines in file order (a FLASER line's odometry fields) and
    returns N poses. Returns N.

    Raises:
        LogReadError: unreadable, or a FLASER or ODOM line too short to hold its poses.
    """
    lines = _read_lines(Path(source))
    rows: list[int] = []
    fields: list[slice] = []
    poses: list[list[float]] = []
    for i, line in enumerate(lines):
        words = line.split()
        if not words or words[0] not in ("FLASER", "ODOM"):
            continue
        try:
            # FLASER n r1..rn x y θ odom_x odom_y odom_θ ...; ODOM x y θ ...
            where = slice(int(words[1]) + 5, int(words[1]) + 8) if words[0] == "FLASER" else slice(1, 4)
            poses.append([float(v) for v in words[where]])
        except (ValueError, IndexError):
            raise LogReadError(f"line {i + 1}: {words[0]} has no pose fields", path=source) from None
        if len(poses[-1]) != 3:
            raise LogReadError(f"line {i + 1}: {words[0]} has no pose fields", path=source)
        rows.append(i)
        fields.append(where)
    replaced = np.asarray(new_poses(np.array(poses, dtype=np.float64).reshape(-1, 3)), dtype=np.float64)
    for i, where, pose in zip(rows, fields, replaced, strict=True):
        words = lines[i].split()
        text = [f"{v:.6f}" for v in pose]
        words[where] = text
        if words[0] == "FLASER":
            words[where.start - 3 : where.start] = text
        lines[i] = " ".join(words)
    Path(output).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return len(rows)
