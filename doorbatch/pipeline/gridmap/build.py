"""The grid stage over passes: occupancy grid mapping with door detection (paper 000, Sec. III).

Per pass: record what was known before it (:func:`~doorbatch.pipeline.gridmap.dynamic.begin_pass`). Per
scan: classify end points against the transient flags (set 1 = dynamic measurements), integrate the rest,
extract potential door leaves from the scan's dynamic points (completed along their lines by the scan's
points in seen-free cells). At the end of a pass: the seen-occupied cells that fell low give set 2, split
by the pass that last hit them (when the leaf stood there), and their leaves. At the end: doors from the
persistent leaf set and the static grid, leaves removed from the static grid. Inputs are scans already in
the map frame, hit points in beam order; reading logs is the caller's business.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorDetectionConfig, GridConfig
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.gridmap.doors import (
    SOURCE_FALLEN,
    DetectedDoor,
    Leaves,
    extract_leaves,
    group_doors,
    remove_leaves,
    scan_leaves,
)
from doorbatch.pipeline.gridmap.dynamic import (
    begin_pass,
    classify_and_integrate,
    take_fallen_cells,
)
from doorbatch.pipeline.gridmap.occupancy import LogOddsGrid, new_grid, to_occupancy_map


class MapScan(NamedTuple):
    """One scan in the map frame: sensor origin (2,), hit points (N, 2), no-return directions (M, 2), and the
    scan's stated maximum range (no-return beams clear no farther)."""

    origin: npt.ArrayLike
    points: npt.ArrayLike
    no_return_dirs: npt.ArrayLike
    range_max_m: float = math.inf


@dataclass(frozen=True)
class GridMapResult:
    """What the grid stage produces.

    Attributes:
        static_map: The static occupancy map (door leaves removed, hinge cells occupied).
        doors: Detected doors.
        grid: The final mapping state (log-odds and flags), for inspection. The transient flags are those
            the end points asked for (lazy); ``dynamic.update_transient`` evaluates them everywhere.
        leaves: The persistent set of potential door leaves the doors were extracted from.
        n_dynamic_points: Scan end points classified as dynamic (set 1) and not integrated.
    """

    static_map: OccupancyMap
    doors: list[DetectedDoor]
    grid: LogOddsGrid
    leaves: Leaves
    n_dynamic_points: int


@dataclass
class GridMapper:
    """Incremental form of :func:`build_grid_map`: ``add_scan`` … ``end_pass`` per pass, then ``finish``."""

    grid_config: GridConfig = field(default_factory=GridConfig)
    door_config: DoorDetectionConfig = field(default_factory=DoorDetectionConfig)
    grid: LogOddsGrid | None = None
    pass_index: int = 0
    pass_start_scan: int = 0
    n_scans: int = 0
    n_dynamic_points: int = 0
    _leaves: list[Leaves] = field(default_factory=list)
    _pass_begun: bool = False

    def add_scan(self, origin: npt.ArrayLike, points: npt.ArrayLike, no_return_dirs: npt.ArrayLike,
                 range_max_m: float = math.inf) -> None:
        """Classify, integrate and mine one scan (map frame; hit points in beam order) for leaves."""
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 2)
        if self.grid is None:
            self.grid = new_grid(self.grid_config, origin)
        if not self._pass_begun:
            begin_pass(self.grid, self.grid_config)
            self._pass_begun = True
        self.grid, cls = classify_and_integrate(self.grid, origin, pts, no_return_dirs, self.grid_config,
                                                self.door_config.door_length_max_m, range_max_m)
        if cls.n_dynamic:
            self.n_dynamic_points += cls.n_dynamic
            # A leaf needs two points a leaf's length apart, or points that may complete a line.
            if cls.n_dynamic >= 2 and (cls.n_support or cls.dynamic_span_m >= self.door_config.door_length_min_m):
                support = pts[cls.support & ~cls.dynamic] if cls.n_support else None
                leaves = scan_leaves(pts[cls.dynamic], support, self.door_config, self.n_scans,
                                     len(self.grid.pass_starts) - 1)
                if len(leaves):
                    self._leaves.append(leaves)
        self.n_scans += 1

    def end_pass(self) -> None:
        """Set 2 of the pass (seen-occupied cells that fell low) and its leaves; starts the next pass."""
        if self.grid is not None and self._pass_begun:
            cells = take_fallen_cells(self.grid, self.grid_config, self.pass_start_scan)
            means = self.grid.cell_means(cells)
            # Eq. (1) per pass that last hit the cells: each such pass held one state of a door, and states
            # of one door that fall in the same pass share the hinge (one cluster, no line) otherwise.
            stood = self.grid.pass_of_scan(self.grid.last_hit_scan.reshape(-1)[cells])
            for q in np.unique(stood):
                leaves = extract_leaves(means[stood == q], self.door_config, len(self.grid.pass_starts) - 1, int(q),
                                        SOURCE_FALLEN)
                if len(leaves):
                    self._leaves.append(leaves)
        self.pass_index += 1
        self.pass_start_scan = self.grid.scan_count if self.grid is not None else 0
        self._pass_begun = False

    def finish(self) -> GridMapResult:
        """Doors from the persistent leaf set; the static map without their leaves."""
        grid = self.grid if self.grid is not None else new_grid(self.grid_config, (0.0, 0.0))
        leaves = Leaves.concat(self._leaves)
        doors = group_doors(leaves, self.door_config, grid)
        remove_leaves(grid, doors, self.door_config, self.grid_config)
        return GridMapResult(to_occupancy_map(grid), doors, grid, leaves, self.n_dynamic_points)


def build_grid_map(passes: Iterable[Iterable[MapScan]], grid_config: GridConfig | None = None,
                   door_config: DoorDetectionConfig | None = None) -> GridMapResult:
    """Occupancy grid and doors from passes of scans in the map frame (each pass: doors stationary).

    Args:
        passes: For each pass, its scans in time order (:class:`MapScan`).
        grid_config: Grid parameters (defaults if None).
        door_config: Door detection parameters (defaults if None).
    """
    mapper = GridMapper(grid_config or GridConfig(), door_config or DoorDetectionConfig())
    for scans in passes:
        for scan in scans:
            mapper.add_scan(*scan)
        mapper.end_pass()
    return mapper.finish()
