"""Writers of the door pose run: door_poses.parquet (DESIGN schema) and the /doorbatch/ annotations
(door boxes on the image as visualization_msgs/ImageMarker, the fitted door line and edges as a
MarkerArray, the goal pose as geometry_msgs/PoseStamped)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io import ros_messages as rm
from doorbatch.io.annotated_mcap import Annotation
from doorbatch.io.parquet import write_table
from doorbatch.io.rundir import map_to_odom_tf
from doorbatch.pipeline.doorpose.fusion import box_edges_px
from doorbatch.pipeline.doorpose.run import DoorPoses, FrameLink

_SPHERE_LIST, _LINE_LIST, _TEXT = 7, 5, 9


def door_pose_columns(result: DoorPoses) -> dict[str, object]:
    """door_poses.parquet columns: one row per estimate."""
    e = result.estimates
    n = len(e)
    return {
        "log": [result.log] * n, "stamp_ns": np.array([x.stamp_ns for x in e], dtype=np.int64),
        "door_id": np.array([x.door_id for x in e], dtype=np.int32),
        "center_x": np.array([x.center[0] for x in e], dtype=np.float64),
        "center_y": np.array([x.center[1] for x in e], dtype=np.float64),
        "yaw": wrap_angle(np.array([x.yaw for x in e], dtype=np.float64)),
        "width": np.array([x.width_m for x in e], dtype=np.float64),
        "handle_side": [x.handle_side for x in e], "fit": [result.fit] * n,
        "goal_x": np.array([x.goal[0] for x in e], dtype=np.float64),
        "goal_y": np.array([x.goal[1] for x in e], dtype=np.float64),
        "goal_yaw": wrap_angle(np.array([x.goal[2] for x in e], dtype=np.float64)),
        "frame": [result.frame] * n,
    }


def write_door_poses(path: Path, result: DoorPoses) -> None:
    """door_poses.parquet, atomically."""
    write_table("door_poses", door_pose_columns(result), path)


def doorpose_annotations(result: DoorPoses, link: FrameLink | None = None) -> Iterator[Annotation]:
    """Per estimate, in time order: /doorbatch/door_boxes (the chosen door box on the image),
    /doorbatch/door_pose (door line, edges, handle side as text), /doorbatch/door_goal (the goal pose); with
    ``link``, also the output frame → odometry frame transform on /tf at the estimate's stamp."""
    links = {} if link is None else {int(t): i for i, t in enumerate(link.stamps_ns.tolist())}
    for k, e in enumerate(sorted(result.estimates, key=lambda x: x.stamp_ns)):
        t = e.stamp_ns
        if link is not None and t in links:
            i = links.pop(t)
            yield map_to_odom_tf(t, link.pose[i], link.odom[i], result.frame, link.odom_frame)
        u0, u1 = box_edges_px(e.box)
        v0, v1 = e.box.center_y - e.box.size_y / 2, e.box.center_y + e.box.size_y / 2
        yield Annotation("/doorbatch/door_boxes", "visualization_msgs/msg/ImageMarker", t,
                         rm.image_box_marker(t, e.camera_frame, "door", k, (u0, v0, u1, v1), (0.9, 0.1, 0.1, 1.0)))
        markers = [
            rm.marker(t, result.frame, "door_line", k, _LINE_LIST, [tuple(e.left), tuple(e.right)],
                      (0.1, 0.8, 0.1, 1.0), 0.04),
            rm.marker(t, result.frame, "door_edges", k, _SPHERE_LIST, [tuple(e.left), tuple(e.right)],
                      (0.1, 0.3, 0.9, 1.0), 0.08),
            rm.marker(t, result.frame, "handle_side", k, _TEXT, [], (1.0, 1.0, 1.0, 1.0), 0.15,
                      text=f"door {e.door_id}: handle {e.handle_side}", position=(float(e.center[0]),
                                                                               float(e.center[1]))),
        ]
        yield Annotation("/doorbatch/door_pose", "visualization_msgs/msg/MarkerArray", t, rm.marker_array(markers))
        yield Annotation("/doorbatch/door_goal", "geometry_msgs/msg/PoseStamped", t,
                         rm.pose_stamped(t, result.frame, float(e.goal[0]), float(e.goal[1]), float(e.goal[2])))
