"""Occupancy maps as nav_msgs/OccupancyGrid holds them, with the cell ↔ world conversions.

The array is indexed ``occupancy[i, j]``: row ``i`` grows with the map's y axis (row 0 is the lowest y,
like OccupancyGrid data, unlike an image), column ``j`` with its x axis. The origin is the pose of the
outer corner of cell (0, 0) in the world (map frame), as in map_server's ``origin: [x, y, yaw]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle

UNKNOWN = -1
FREE = 0
OCCUPIED = 100

Int8Array = npt.NDArray[np.int8]
IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True, eq=False)
class OccupancyMap:
    """A 2D occupancy grid in the ROS OccupancyGrid convention.

    Attributes:
        occupancy: (height, width) int8: -1 unknown, 0..100 occupied probability in percent; row 0 is
            the lowest y.
        resolution_m: Cell edge length (m).
        origin_x_m: World x of the outer corner of cell (0, 0) (m).
        origin_y_m: World y of that corner (m).
        origin_yaw_rad: Rotation of the grid about that corner (rad, CCW).

    Equality is identity (the array makes ``==`` ambiguous); compare fields with NumPy.
    """

    occupancy: Int8Array
    resolution_m: float
    origin_x_m: float = 0.0
    origin_y_m: float = 0.0
    origin_yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        """Check shape, dtype, value range, and a positive finite resolution.

        Raises:
            ValueError: Any of these is wrong.
        """
        grid = self.occupancy
        if not isinstance(grid, np.ndarray) or grid.ndim != 2 or grid.dtype != np.int8:
            raise ValueError("occupancy must be a 2-D int8 array")
        if grid.size and (int(grid.min()) < UNKNOWN or int(grid.max()) > OCCUPIED):
            raise ValueError("occupancy values must be -1 (unknown) or 0..100")
        if not (math.isfinite(self.resolution_m) and self.resolution_m > 0.0):
            raise ValueError(f"resolution_m must be positive and finite, got {self.resolution_m}")
        origin = (self.origin_x_m, self.origin_y_m, self.origin_yaw_rad)
        if not all(math.isfinite(v) for v in origin):
            raise ValueError(f"origin must be finite, got {origin}")

    @property
    def width(self) -> int:
        """Number of columns (cells along x)."""
        return int(self.occupancy.shape[1])

    @property
    def height(self) -> int:
        """Number of rows (cells along y)."""
        return int(self.occupancy.shape[0])

    def _rotation(self) -> FloatArray:
        c, s = math.cos(self.origin_yaw_rad), math.sin(self.origin_yaw_rad)
        return np.array([[c, -s], [s, c]], dtype=np.float64)

    def world_to_cell(self, xy_m: npt.ArrayLike) -> IntArray:
        """The cell (row i, column j) holding each world point.

        Args:
            xy_m: (..., 2) world points (x, y) in m.

        Returns:
            (..., 2) int64 indices ``[i, j]`` so that ``occupancy[ij[..., 0], ij[..., 1]]`` is the cell;
            points outside the grid give indices outside it (see :meth:`contains`).
        """
        return np.floor(self.world_to_grid(xy_m)).astype(np.int64)

    def world_to_grid(self, xy_m: npt.ArrayLike, direction: bool = False) -> FloatArray:
        """World points (or, with ``direction``, world vectors: rotated only) in fractional cell units ``[i, j]``
        (row, column; cell (i, j) spans [i, i + 1) × [j, j + 1)), so that :meth:`world_to_cell` is their floor."""
        xy = np.asarray(xy_m, dtype=np.float64)
        offset = (0.0, 0.0) if direction else (self.origin_x_m, self.origin_y_m)
        local = (xy - offset) @ self._rotation()  # R^T · (p − o)
        return np.asarray(local[..., ::-1] / self.resolution_m, dtype=np.float64)

    def cell_to_world(self, ij: npt.ArrayLike) -> FloatArray:
        """The world point (x, y) in m of the center of each cell.

        Args:
            ij: (..., 2) cell indices ``[i, j]`` (row, column); fractional indices are allowed.
        """
        cells = np.asarray(ij, dtype=np.float64)
        local = (cells[..., ::-1] + 0.5) * self.resolution_m
        return local @ self._rotation().T + (self.origin_x_m, self.origin_y_m)

    def contains(self, ij: npt.ArrayLike) -> BoolArray:
        """Whether each cell index ``[i, j]`` lies inside the grid."""
        cells = np.asarray(ij)
        i, j = cells[..., 0], cells[..., 1]
        return np.asarray((i >= 0) & (i < self.height) & (j >= 0) & (j < self.width), dtype=np.bool_)


@dataclass(frozen=True)
class DoorSet:
    """Doors as arrays (doors.parquet's columns): hinge (D, 2), leaf length (m), closed_yaw (global direction
    hinge → free end at angle 0), and the opening range [angle_min, angle_max] relative to it (CCW +)."""

    hinge: FloatArray
    length: FloatArray
    closed_yaw: FloatArray
    angle_min: FloatArray
    angle_max: FloatArray
    door_id: npt.NDArray[np.int32] | None = None  # doors.parquet's door_id per row; None: the row numbers

    def __len__(self) -> int:
        return int(self.hinge.shape[0])

    @property
    def ids(self) -> npt.NDArray[np.int32]:
        """Each door's id (doors.parquet's door_id, which outputs name it by), the row number where not given."""
        if self.door_id is None:
            return np.arange(len(self), dtype=np.int32)
        return np.asarray(self.door_id, dtype=np.int32)

    @classmethod
    def empty(cls) -> DoorSet:
        """No doors (a plain map_server map)."""
        return cls(np.zeros((0, 2)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))

    @property
    def range_global(self) -> tuple[FloatArray, FloatArray]:
        """Leaf directions at the two ends of the opening range, in the map frame."""
        return wrap_angle(self.closed_yaw + self.angle_min), wrap_angle(self.closed_yaw + self.angle_max)
