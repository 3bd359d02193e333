"""preview.png: a map drawn for a person — static map, doors with their opening arcs, trajectories."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import numpy.typing as npt

from doorbatch.io.atomic import atomic_path
from doorbatch.maps import OccupancyMap

_COLORS_BGR = [(200, 90, 30), (40, 160, 40), (30, 120, 230), (160, 40, 160), (20, 170, 170)]


@dataclass(frozen=True)
class PreviewDoor:
    """A door to draw: hinge, leaf length, closed direction, opening range (rad); ``moved`` doors in red."""

    hinge_x: float
    hinge_y: float
    length: float
    closed_yaw: float
    angle_min: float
    angle_max: float
    moved: bool = True


def _pixel_scale(occ: OccupancyMap, max_side_px: int) -> int:
    return int(max(1, min(4, max_side_px // max(occ.width, occ.height, 1))))


def crop_to_known(occ: OccupancyMap, margin_cells: int = 20) -> OccupancyMap:
    """The map cut to the bounding box of its known cells plus a margin (same world coordinates)."""
    rows, cols = np.nonzero(occ.occupancy >= 0)
    if rows.size == 0 or occ.origin_yaw_rad != 0.0:
        return occ
    r0, r1 = max(0, rows.min() - margin_cells), min(occ.height, rows.max() + margin_cells + 1)
    c0, c1 = max(0, cols.min() - margin_cells), min(occ.width, cols.max() + margin_cells + 1)
    return OccupancyMap(occ.occupancy[r0:r1, c0:c1].copy(), occ.resolution_m,
                        occ.origin_x_m + c0 * occ.resolution_m, occ.origin_y_m + r0 * occ.resolution_m, 0.0)


def render_preview(occ: OccupancyMap, doors: Sequence[PreviewDoor] = (),
                   trajectories: Sequence[npt.NDArray[np.float64]] = (), max_side_px: int = 2000,
                   walls: npt.NDArray[np.float64] | None = None) -> npt.NDArray[np.uint8]:
    """BGR image of the known part of the map: free white, occupied black, unknown grey; doors red (moved)
    or orange (never seen moving) with their opening arcs; trajectories as coloured lines; ``walls``
    (K, 2, 2) wall segments of the em stage as dark blue lines."""
    occ = crop_to_known(occ)
    scale = _pixel_scale(occ, max_side_px)
    grid = occ.occupancy
    gray = np.full(grid.shape, 205, dtype=np.uint8)
    gray[(grid >= 0) & (grid < 20)] = 254
    gray[grid >= 65] = 0
    img = cv2.cvtColor(np.flipud(gray), cv2.COLOR_GRAY2BGR)
    img = cv2.resize(img, (occ.width * scale, occ.height * scale), interpolation=cv2.INTER_NEAREST)

    def px(xy: npt.ArrayLike) -> npt.NDArray[np.int32]:
        ij = (np.asarray(xy, dtype=np.float64).reshape(-1, 2) - [occ.origin_x_m, occ.origin_y_m]) / occ.resolution_m
        cols = ij[:, 0] * scale
        rows = (occ.height - ij[:, 1]) * scale
        return np.stack([cols, rows], axis=1).round().astype(np.int32)

    for k, traj in enumerate(trajectories):
        if len(traj) > 1:
            cv2.polylines(img, [px(traj[:, :2])], False, _COLORS_BGR[k % len(_COLORS_BGR)], 1, cv2.LINE_AA)
    for seg in ([] if walls is None else walls):
        a, b = px(seg)
        cv2.line(img, tuple(a), tuple(b), (140, 40, 0), 2, cv2.LINE_AA)
    for door in doors:
        color = (0, 0, 230) if door.moved else (0, 140, 255)
        hinge = np.array([door.hinge_x, door.hinge_y])
        arc = door.closed_yaw + np.linspace(door.angle_min, door.angle_max, 24)
        arc_pts = hinge + door.length * np.stack([np.cos(arc), np.sin(arc)], axis=1)
        cv2.polylines(img, [px(arc_pts)], False, color, 1, cv2.LINE_AA)
        for yaw in (door.closed_yaw + door.angle_min, door.closed_yaw + door.angle_max):
            end = hinge + door.length * np.array([np.cos(yaw), np.sin(yaw)])
            cv2.line(img, tuple(px(hinge)[0]), tuple(px(end)[0]), color, 2, cv2.LINE_AA)
        cv2.circle(img, tuple(px(hinge)[0]), max(2, scale + 1), color, -1, cv2.LINE_AA)
    return np.asarray(img, dtype=np.uint8)


def write_preview(path: Path, image: npt.NDArray[np.uint8]) -> None:
    """Write a PNG atomically."""
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise ValueError("PNG encoding failed")
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.tobytes())
