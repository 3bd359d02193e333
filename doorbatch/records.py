"""Typed records that readers yield and stages consume.

Every stamp is int64 nanoseconds. ``stamp_ns`` is the message's header time (the time the data was
measured); ``log_time_ns`` is the time the message was recorded into the log. Poses are planar (x, y, yaw)
because every stage is 2D; transforms keep full 3D so that tilted or upside-down lasers are handled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
UInt8Array = npt.NDArray[np.uint8]
BoolArray = npt.NDArray[np.bool_]


class Role(StrEnum):
    """What a topic is for (DESIGN.md, Inputs)."""

    SCAN = "scan"
    ODOMETRY = "odometry"
    REFERENCE = "reference"
    TRANSFORMS = "transforms"
    COLORS = "colors"
    IMAGE = "image"
    CAMERA_INFO = "camera_info"
    DETECTIONS = "detections"


@dataclass(frozen=True, slots=True)
class Scan:
    """One planar laser scan, as sensor_msgs/LaserScan holds it (ranges as float32).

    Beam i points at ``angle_min + i * angle_increment`` in the laser frame; a negative increment
    (upside-down lidar) is legal. NaN: no information. +inf or ≥ range_max: no return within range.
    """

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: Float32Array
    intensities: Float32Array | None = None
    # Time between beams (LaserScan.time_increment): beam i was measured at stamp + i · time_increment_s (the stamp
    # is the first beam's time); 0 where the driver leaves it unset.
    time_increment_s: float = 0.0

    @property
    def angles(self) -> FloatArray:
        """Beam angles in the laser frame (rad)."""
        return self.angle_min + self.angle_increment * np.arange(self.ranges.shape[0], dtype=np.float64)

    @property
    def sweep_s(self) -> float:
        """Time from the first beam to the last, |time_increment| · (beams − 1)."""
        return abs(self.time_increment_s) * max(int(self.ranges.shape[0]) - 1, 0)


@dataclass(frozen=True, slots=True)
class Pose2D:
    """A planar pose stamped in time: odometry (frame odom) or a reference pose (frame map)."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    child_frame_id: str
    x: float
    y: float
    yaw: float
    # nav_msgs/Odometry's twist in child_frame_id (m/s, rad/s): a base that fills only the twist leaves the pose at 0
    vx: float = 0.0
    vy: float = 0.0
    wz: float = 0.0


@dataclass(frozen=True, slots=True)
class Transform:
    """One rigid transform parent→child: p_parent = R(rotation_xyzw) · p_child + translation."""

    stamp_ns: int
    parent: str
    child: str
    translation: FloatArray  # (3,)
    rotation_xyzw: FloatArray  # (4,) unit quaternion
    static: bool = False
    log_time_ns: int = 0  # when the log recorded it (0: not known)


@dataclass(frozen=True, slots=True)
class BeamColors:
    """Per-beam colors aligned with a scan: one point and one RGB triple per beam (PointCloud2 x,y,z,rgb)."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    points: Float32Array  # (N, 3)
    rgb: UInt8Array  # (N, 3)


@dataclass(frozen=True, slots=True)
class Image:
    """A camera image decoded to an array (H, W) or (H, W, 3) in RGB order."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    pixels: UInt8Array
    encoding: str


@dataclass(frozen=True, slots=True)
class CameraInfo:
    """Pinhole intrinsics and distortion (sensor_msgs/CameraInfo)."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    width: int
    height: int
    distortion_model: str
    d: FloatArray
    k: FloatArray  # (3, 3)
    p: FloatArray  # (3, 4)


@dataclass(frozen=True, slots=True)
class Detection:
    """One 2D detection box in pixels (center and size), with its class name and score."""

    class_id: str
    score: float
    center_x: float
    center_y: float
    size_x: float
    size_y: float


def class_name(class_id: str, class_names: list[str] | tuple[str, ...]) -> str:
    """A box's class: its id when that is a name, else the name at that index of the detector's label list
    (vision_msgs ids are indices a label map resolves: Isaac ROS publishes "0", Noetic int64 0). The config's
    ``doorpose.door_class`` and ``handle_class`` are resolved the same way, so a name or an id may name them."""
    if class_id in class_names or not class_id.isdigit() or int(class_id) >= len(class_names):
        return class_id
    return class_names[int(class_id)]


@dataclass(frozen=True, slots=True)
class Detections:
    """All detections of one image (vision_msgs/Detection2DArray)."""

    stamp_ns: int
    log_time_ns: int
    frame_id: str
    detections: tuple[Detection, ...] = field(default_factory=tuple)


Record = Scan | Pose2D | Transform | BeamColors | Image | CameraInfo | Detections


class RoleMessage(NamedTuple):
    """A record with the role and topic it came from. Transforms come one record per transform."""

    role: Role
    topic: str
    record: Record
