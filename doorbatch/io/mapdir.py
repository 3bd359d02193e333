"""The map directory of ``doorbatch map``: map.yaml + map.pgm, doors.parquet, preview.png, manifest.json."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io.map_server import write_map
from doorbatch.io.parquet import read_table, write_table
from doorbatch.io.preview import PreviewDoor, render_preview, write_preview
from doorbatch.maps import DoorSet, OccupancyMap


def doors_columns(doors: Sequence[PreviewDoor], n_observations: Sequence[int], source: str,
                  ) -> dict[str, object]:
    """doors.parquet columns (DESIGN schema), door_id in the given order, angles wrapped to (−π, π]."""
    n = len(doors)
    return {
        "door_id": np.arange(n, dtype=np.int32),
        "hinge_x": [d.hinge_x for d in doors],
        "hinge_y": [d.hinge_y for d in doors],
        "length": [d.length for d in doors],
        "closed_yaw": wrap_angle([d.closed_yaw for d in doors]) if n else [],
        "angle_min": [d.angle_min for d in doors],
        "angle_max": [d.angle_max for d in doors],
        "n_observations": np.asarray(n_observations, dtype=np.int32),
        "source": [source] * n,
        "moved": [d.moved for d in doors],
    }


def write_map_dir(out: Path, static_map: OccupancyMap, doors: Sequence[PreviewDoor], n_observations: Sequence[int],
                  source: str, trajectories: Sequence[np.ndarray], walls: np.ndarray | None = None) -> list[Path]:
    """Write map.yaml/map.pgm, doors.parquet and preview.png (with ``walls`` (K, 2, 2) segments of the em
    stage drawn, when given) into ``out``; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    write_map(static_map, out / "map.yaml")
    write_table("doors", doors_columns(doors, n_observations, source), out / "doors.parquet")
    write_preview(out / "preview.png", render_preview(static_map, doors, trajectories, walls=walls))
    return [out / "map.yaml", out / "map.pgm", out / "doors.parquet", out / "preview.png"]


def read_door_set(map_dir: Path) -> DoorSet:
    """doors.parquet of a map directory as arrays (any source: grid or em). A map without the file has
    no doors (a plain map_server map from another SLAM tool)."""
    path = map_dir / "doors.parquet"
    if not path.exists():
        return DoorSet(np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))
    return door_set_of(read_table("doors", path).to_pydict())


def door_set_of(t: dict[str, list[Any]]) -> DoorSet:
    """doors.parquet columns (``to_pydict``) as a DoorSet."""
    return DoorSet(np.array([t["hinge_x"], t["hinge_y"]], dtype=np.float64).T.reshape(-1, 2),
                   np.asarray(t["length"], dtype=np.float64), np.asarray(t["closed_yaw"], dtype=np.float64),
                   np.asarray(t["angle_min"], dtype=np.float64), np.asarray(t["angle_max"], dtype=np.float64))
