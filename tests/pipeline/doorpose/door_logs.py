"""Logs of a robot in front of a simulated door, written with the real writers (for the doorpose tests)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doorbatch.geometry.se2 import compose, inverse
from doorbatch.io import ros_messages as m
from doorbatch.sim.door_scene import CAMERA_FRAME, LASER_FRAME, DoorScene, observe
from doorbatch.sim.sensors import camera_rotation_xyzw
from tests.conftest import T0, write_messages

STEP_NS = 200_000_000


def door_log(path: Path, scene: DoorScene, poses: np.ndarray, rng: np.random.Generator, images: bool = False,
             other_cameras: tuple[tuple[str, str, float], ...] = (), info_topic: str = "/camera/camera_info",
             camera_xyzw: tuple[float, float, float, float] | None = None, unset_box_stamps: bool = False,
             image_topic: str = "/camera/image_raw", depth_topic: str | None = None, box_delay_ns: int = 0,
             image_every: int = 1, box_frame: str = CAMERA_FRAME, boxes_seen_late: bool = False,
             map_to_odom: tuple[float, float, float] | None = None) -> Path:
    """A log of the robot at ``poses`` in a door scene: static TF, camera_info, and per pose ground truth, a
    scan, the detector's boxes (5 ms later) and, with ``images``, the rendered image. ``other_cameras``: more
    CameraInfo topics (topic, frame, focal length in px), as a RealSense publishes for depth and infrared;
    ``camera_xyzw``: another camera mount rotation; ``unset_box_stamps``: detections with header stamp 0;
    ``depth_topic``: also a 16UC1 depth image per pose there; ``box_delay_ns``: boxes stamped (and logged) this
    much after their image, as a detector that stamps on publishing (negative: before it, a jittering clock);
    ``image_every``: the recording kept only every n-th image; ``box_frame``: the boxes' header frame (a detector
    that names the camera's body frame, not its optical frame); ``boxes_seen_late``: the boxes (and image) seen
    from where the robot is at their stamp (the poses interpolated), not from the scan's pose; ``map_to_odom``:
    also wheel odometry on /odom, in an odom frame placed there on the map (x, y, yaw)."""
    cam = scene.camera_model
    lm = scene.laser
    msgs: list[tuple[str, str, int, object]] = [
        ("/tf_static", "tf2_msgs/msg/TFMessage", T0, m.tf_message([
            m.planar_transform(T0, "base_link", LASER_FRAME, lm.mount_xy_m[0], lm.mount_xy_m[1], 0.0, z=lm.mount_z_m),
            m.transform_stamped(T0, "base_link", CAMERA_FRAME, (*cam.mount_xy_m, cam.mount_z_m),
                                camera_xyzw or tuple(camera_rotation_xyzw(cam.mount_yaw_rad)))])),
        (info_topic, "sensor_msgs/msg/CameraInfo", T0, m.camera_info(T0, CAMERA_FRAME, cam.width, cam.height, cam.k)),
        *((topic, "sensor_msgs/msg/CameraInfo", T0,
           m.camera_info(T0, frame, cam.width, cam.height, [[f, 0, cam.width / 2], [0, f, cam.height / 2], [0, 0, 1]]))
          for topic, frame, f in other_cameras),
    ]
    for i, pose in enumerate(poses):
        t = T0 + STEP_NS * (i + 1)
        x, y, yaw = (float(v) for v in pose)
        obs = observe(scene, pose, rng)
        ranges = obs.ranges
        if boxes_seen_late:
            step = poses[i + 1] - pose if i + 1 < len(poses) else pose - poses[i - 1]
            obs = observe(scene, pose + step * (5_000_000 + box_delay_ns) / STEP_NS, rng)
        boxes = [(d.class_id, d.score, d.center_x, d.center_y, d.size_x, d.size_y) for d in obs.detections]
        msgs += [
            ("/ground_truth", "nav_msgs/msg/Odometry", t, m.odometry(t, "map", "base_link", x, y, yaw)),
            ("/scan", "sensor_msgs/msg/LaserScan", t,
             m.laser_scan(t, LASER_FRAME, lm.angle_min_rad, lm.angle_increment_rad, lm.range_min_m, lm.range_max_m,
                          ranges)),
            ("/detections", "vision_msgs/msg/Detection2DArray", t + 5_000_000 + box_delay_ns,
             m.detection_array(0 if unset_box_stamps else t + 5_000_000 + box_delay_ns, box_frame, boxes)),
        ]
        if map_to_odom is not None:
            ox, oy, oyaw = compose(inverse(np.asarray(map_to_odom, dtype=np.float64)), pose)
            msgs.append(("/odom", "nav_msgs/msg/Odometry", t, m.odometry(t, "odom", "base_link", ox, oy, oyaw)))
        if images and i % image_every == 0:
            msgs.append((image_topic, "sensor_msgs/msg/Image", t + 5_000_000,
                         m.image_rgb8(t + 5_000_000, CAMERA_FRAME, obs.image)))
        if images and depth_topic is not None:
            depth = m.image_rgb8(t + 5_000_000, "depth_optical", np.zeros((4, 4), np.uint8))
            depth.encoding, depth.step, depth.data = "16UC1", 8, np.zeros(32, np.uint8)
            msgs.append((depth_topic, "sensor_msgs/msg/Image", t + 5_000_000, depth))
    return write_messages(path, sorted(msgs, key=lambda msg: msg[2]))
