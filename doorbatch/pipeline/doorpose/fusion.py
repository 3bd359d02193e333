"""Door pose from one door box and one laser scan (paper 003, Sec. III-B, Fig. 3).

In the camera's horizontal plane (x right, z forward; the paper's 2D assumption is a level camera, and a tilted
one is levelled: its rays and the laser's points are turned into the level frame of
:func:`~doorbatch.geometry.camera.level_rotation`):

1. the highest-scoring door box whose left and right edges keep off the image border;
2. bearings β_l, β_r of its left and right edges (intrinsics and distortion): the innermost bearing of each edge
   column (:func:`~doorbatch.geometry.camera.box_edge_bearings`; a level undistorted camera gives every row the
   horizon row c_y's, the paper's constant row);
3. door points: laser hits, moved into the camera frame by TF, with β_l ≤ atan2(x, z) ≤ β_r and z > 0;
4. a line z = a + b·x through them (``naive``, ``lsq`` or ``ransac``, see :mod:`.line_fit`);
5. door edges where the rays meet the line: t = a / (cos β − b·sin β), e = t·(sin β, cos β);
6. centre c = (e_l + e_r)/2, width |e_r − e_l| (outside [door_width_min_m, door_width_max_m]: not a door),
   normal n ⊥ (e_r − e_l) pointing to the camera, and the goal g = c + offset·n facing the door (heading −n);
7. handle side: the best handle box whose centre lies in the door box, left or right of the box centre.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorPoseConfig
from doorbatch.geometry.camera import PinholeCamera, box_edge_bearings
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.pipeline.doorpose.line_fit import DepthLine, LineFit, fit_line
from doorbatch.records import Detection, class_name

FloatArray = npt.NDArray[np.float64]


class HandleSide(StrEnum):
    """Which half of the door box holds the handle, as the camera sees it."""

    LEFT = "left"
    RIGHT = "right"
    NONE = "none"


def box_edges_px(box: Detection) -> tuple[float, float]:
    """Left and right edge columns (u_min, u_max) of a box given by centre and size."""
    return box.center_x - box.size_x / 2, box.center_x + box.size_x / 2


def usable_detections(detections: Sequence[Detection], config: DoorPoseConfig) -> list[Detection]:
    """The boxes at or above ``confidence_threshold`` (a detector may publish everything above 0.01), with
    their classes resolved by :func:`class_name`."""
    return [replace(d, class_id=class_name(d.class_id, config.class_names)) for d in detections
            if d.score >= config.confidence_threshold]


def door_box(usable: Sequence[Detection], image_width_px: int, config: DoorPoseConfig) -> Detection | None:
    """The door box among one image's :func:`usable_detections` (:func:`select_door_box`, ``door_class``
    resolved by :func:`~doorbatch.records.class_name`)."""
    return select_door_box(usable, image_width_px, class_name(config.door_class, config.class_names),
                           config.border_margin_px)


def select_door_box(detections: Sequence[Detection], image_width_px: int, door_class: str,
                    border_margin_px: float) -> Detection | None:
    """The highest-scoring door box that does not reach the left or right image border (Sec. III-B).

    The image spans u ∈ [−0.5, W − 0.5]; a box within ``border_margin_px`` of either end is cut by it.
    """
    lo, hi = -0.5 + border_margin_px, image_width_px - 0.5 - border_margin_px
    inside = [d for d in detections if d.class_id == door_class and box_edges_px(d)[0] > lo
              and box_edges_px(d)[1] < hi and d.size_x > 0]
    return max(inside, key=lambda d: d.score) if inside else None


def handle_side(door: Detection, detections: Sequence[Detection], handle_class: str) -> HandleSide:
    """Side of the best handle box whose centre lies inside the door box: left or right of the door box's
    centre column (Sec. III-B); NONE without such a handle."""
    u0, u1 = box_edges_px(door)
    v0, v1 = door.center_y - door.size_y / 2, door.center_y + door.size_y / 2
    inside = [h for h in detections if h.class_id == handle_class and u0 <= h.center_x <= u1
              and v0 <= h.center_y <= v1]
    if not inside:
        return HandleSide.NONE
    best = max(inside, key=lambda h: h.score)
    return HandleSide.LEFT if best.center_x < door.center_x else HandleSide.RIGHT


@dataclass(frozen=True)
class CameraDoor:
    """A door estimated in the camera's horizontal plane, (x right, z forward) metres."""

    left_xz: FloatArray  # (2,) where the left ray meets the line
    right_xz: FloatArray  # (2,)
    center_xz: FloatArray  # (2,)
    normal_xz: FloatArray  # (2,) unit, pointing to the camera
    width_m: float
    goal_xz: FloatArray  # (2,) centre + offset·normal; the goal heading is −normal
    handle_side: HandleSide
    box: Detection
    door_points_xz: FloatArray  # (N, 2) points between the rays
    line: DepthLine
    wall_turn_deg: float = float("nan")  # the door line's angle to the wall beside it (:func:`wall_turn_deg`)


def door_points(points_cam: FloatArray, bearing_left: float, bearing_right: float) -> FloatArray:
    """(x, z) of the points (N, 3, optical frame) in front of the camera between the two ray bearings."""
    x, z = points_cam[:, 0], points_cam[:, 2]
    beta = np.arctan2(x, z)
    keep = (z > 0.0) & (beta >= bearing_left) & (beta <= bearing_right) & np.isfinite(x) & np.isfinite(z)
    return np.stack([x[keep], z[keep]], axis=1)


def ray_line_intersection(bearing: float, line: DepthLine) -> FloatArray | None:
    """Where the ray t·(sin β, cos β), t > 0, meets z = a + b·x; None if parallel or behind."""
    denom = np.cos(bearing) - line.slope * np.sin(bearing)
    if abs(denom) < 1e-9:
        return None
    t = line.intercept_m / denom
    return None if t <= 0.0 else np.array([t * np.sin(bearing), t * np.cos(bearing)])


def wall_turn_deg(left: FloatArray, right: FloatArray, line: DepthLine, points_xz: FloatArray,
                  config: DoorPoseConfig) -> float:
    """Angle (deg, 0-90) between a door's line and the wall's beside it; NaN where under ``min_wall_points`` are
    seen there.

    The wall: a RANSAC line (residual ``wall_residual_m``) through the laser points (x, z) that lie, seen from the
    camera, within ``wall_check_m`` beyond a door edge along the door's line, on each side on its own; the smaller
    angle of the two counts (beside a room's corner one side may show the other wall). A closed door, flush with its
    wall or recessed in it, runs along the wall (about 0°); a door standing open shows its leaf between the box's
    rays, turned from the wall by its opening angle, and the pose is the leaf's, not the doorway's (paper 003
    approaches closed doors). Its RANSAC draws from a generator of its own, so that the door fits' stream, and their
    results, are those without it.
    """
    along = (right - left) / float(np.hypot(*(right - left)))
    ends = np.stack([left, right, left - config.wall_check_m * along, right + config.wall_check_m * along])
    b_l, b_r, beyond_l, beyond_r = (float(b) for b in np.arctan2(ends[:, 0], ends[:, 1]))
    x, z = points_xz[:, 0], points_xz[:, 1]
    beta = np.arctan2(x, z)
    ahead = (z > 0.0) & np.isfinite(beta)
    left_side = ahead & (beta >= min(beyond_l, b_l)) & (beta < b_l)
    right_side = ahead & (beta > b_r) & (beta <= max(beyond_r, b_r))
    turns = []
    for side in (left_side, right_side):  # each on its own: beside a room's corner one side shows the other wall
        if int(side.sum()) < config.min_wall_points:
            continue
        wall = fit_line(points_xz[side], LineFit.RANSAC, config.ransac_max_trials, config.wall_residual_m,
                        np.random.default_rng(0))
        if wall is not None and int(wall.inliers.sum()) >= config.min_wall_points:
            turn = abs(math.degrees(math.atan(wall.slope) - math.atan(line.slope)))
            turns.append(min(turn, 180.0 - turn))
    return min(turns) if turns else float("nan")


def estimate_door(camera: PinholeCamera, detections: Sequence[Detection], points_cam: FloatArray,
                  config: DoorPoseConfig, rng: np.random.Generator, fit: LineFit | None = None,
                  level: FloatArray | None = None) -> CameraDoor | None:
    """One door estimate from one image's boxes and one scan's points in the camera frame (module docstring), in
    the level frame ``level`` turns the camera's into (:func:`~doorbatch.geometry.camera.level_rotation`; None: the
    camera is level); None when no door box is usable, too few points fall between the rays, the rays miss the
    line, or the width is not a door's."""
    usable = usable_detections(detections, config)
    box = door_box(usable, camera.width, config)
    if box is None:
        return None
    u0, u1 = box_edges_px(box)
    beta_l, beta_r = box_edge_bearings(camera, u0, u1, box.center_y - box.size_y / 2, box.center_y + box.size_y / 2,
                                       level)
    points = points_cam if level is None else points_cam @ np.asarray(level, dtype=np.float64).T
    pts = door_points(points, beta_l, beta_r)
    if pts.shape[0] < config.min_door_points:
        return None
    method = LineFit(config.fit) if fit is None else fit
    line = fit_line(pts, method, config.ransac_max_trials, config.ransac_residual_m, rng)
    if line is None:
        return None
    left, right = ray_line_intersection(beta_l, line), ray_line_intersection(beta_r, line)
    if left is None or right is None:
        return None
    center = (left + right) / 2
    along = right - left
    width = float(np.hypot(*along))
    if not config.door_width_min_m <= width <= config.door_width_max_m or width <= 0.0:
        return None
    normal = np.array([-along[1], along[0]]) / width
    if normal @ center > 0.0:  # point from the door toward the camera at the origin
        normal = -normal
    return CameraDoor(left, right, center, normal, width, center + config.goal_offset_m * normal,
                      handle_side(box, usable, class_name(config.handle_class, config.class_names)), box, pts, line,
                      wall_turn_deg(left, right, line, points[:, [0, 2]], config))


@dataclass(frozen=True)
class PlanarDoor:
    """A door pose in a planar frame: centre, yaw of the normal toward the robot, width, goal pose."""

    center: FloatArray  # (2,)
    yaw: float
    width_m: float
    goal: FloatArray  # (3,) x, y, yaw (facing the door: yaw + π)
    left: FloatArray  # (2,) door edges
    right: FloatArray  # (2,)


def camera_plane_to_base(camera_to_base: FloatArray, level: FloatArray | None = None
                         ) -> tuple[FloatArray, FloatArray]:
    """(origin (2,), 2×2 matrix) taking camera-plane (x, z) to base_link (x, y): p = o + [R_x | R_z]·(x, z),
    with R_x, R_z the x and z axes of the level frame (``level`` turns optical vectors into it; None: the optical
    frame, a level camera) in base_link, projected to the floor."""
    rot = camera_to_base[:3, :3] if level is None else camera_to_base[:3, :3] @ np.asarray(level).T
    return camera_to_base[:2, 3].copy(), np.stack([rot[:2, 0], rot[:2, 2]], axis=1)


def to_planar(door: CameraDoor, camera_to_base: FloatArray, robot_pose: FloatArray | None = None,
              level: FloatArray | None = None) -> PlanarDoor:
    """The door in base_link (from the 4×4 optical→base_link transform and the level frame the door was estimated
    in, as :func:`estimate_door` took it), or in the robot pose's frame."""
    origin, mat = camera_plane_to_base(camera_to_base, level)
    pts = np.stack([door.center_xz, door.left_xz, door.right_xz, door.goal_xz]) @ mat.T + origin
    n = mat @ door.normal_xz
    yaw = float(np.arctan2(n[1], n[0]))
    if robot_pose is not None:
        x, y, th = (float(v) for v in robot_pose)
        c, s = np.cos(th), np.sin(th)
        pts = pts @ np.array([[c, s], [-s, c]]) + np.array([x, y])
        yaw += th
    yaw = float(wrap_angle(yaw))
    goal = np.array([pts[3, 0], pts[3, 1], float(wrap_angle(yaw + np.pi))])
    return PlanarDoor(pts[0], yaw, door.width_m, goal, pts[1], pts[2])
