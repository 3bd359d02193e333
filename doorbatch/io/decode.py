"""Turn deserialized ROS messages (rosbags objects, ROS 1 or ROS 2 layout) into doorbatch records.

Field names of the types we read are the same in ROS 1 and ROS 2 as rosbags represents them (time is
``sec``/``nanosec`` in both), except vision_msgs, whose ROS 1 and ROS 2 layouts differ; both are handled.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import replace
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from doorbatch.errors import LogContentError
from doorbatch.records import (
    BeamColors,
    CameraInfo,
    Detection,
    Detections,
    Image,
    Pose2D,
    Record,
    Role,
    Scan,
    Transform,
)

LASERSCAN = "sensor_msgs/msg/LaserScan"
MULTI_ECHO_LASERSCAN = "sensor_msgs/msg/MultiEchoLaserScan"
ODOMETRY = "nav_msgs/msg/Odometry"
POSE_STAMPED = "geometry_msgs/msg/PoseStamped"
MODEL_STATES = "gazebo_msgs/msg/ModelStates"  # Gazebo's poses of every model: a simulator's ground truth
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TF_MESSAGE_ROS1_LEGACY = "tf/msg/tfMessage"  # /tf of ROS 1 before Hydro: the same layout
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
DETECTION2D_ARRAY = "vision_msgs/msg/Detection2DArray"

# Tolerance on the beam count implied by (angle_max − angle_min) / angle_increment + 1.
_BEAM_COUNT_SLACK = 1


def stamp_to_ns(stamp: Any) -> int:
    """builtin_interfaces/Time (or ROS 1 time as rosbags gives it) → int64 nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def yaw_from_quaternion(x: float, y: float, z: float, w: float) -> float:
    """Heading (rotation about z) of a unit quaternion, in (−π, π]."""
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def expected_beam_count(angle_min: float, angle_max: float, angle_increment: float) -> int:
    """Number of beams a LaserScan's angles describe (``round((max − min) / inc) + 1``)."""
    if angle_increment == 0.0 or not math.isfinite(angle_increment):
        return -1
    return round((angle_max - angle_min) / angle_increment) + 1


def _first_echoes(beams: Any) -> npt.NDArray[np.float32]:
    """Per beam of a MultiEchoLaserScan its first echo (NaN where a beam has none), as Cartographer reads them."""
    return np.array([b.echoes[0] if len(b.echoes) else np.nan for b in beams], dtype=np.float32)


def decode_scan(msg: Any, log_time_ns: int, topic: str, msgtype: str = LASERSCAN) -> Scan:
    """sensor_msgs/LaserScan (or MultiEchoLaserScan, each beam's first echo) → :class:`Scan`, checking that
    ranges match the angles.

    Raises:
        LogContentError: zero angle increment, or a ranges length that disagrees with the angles.
    """
    multi = msgtype == MULTI_ECHO_LASERSCAN
    # copies: the deserializer's arrays are views into the whole message's buffer, which a recording that keeps
    # every scan's ranges would otherwise keep alive (twice the memory on a laser with intensities)
    ranges = _first_echoes(msg.ranges) if multi else np.array(msg.ranges, dtype=np.float32)
    expected = expected_beam_count(msg.angle_min, msg.angle_max, msg.angle_increment)
    if expected < 0:
        raise LogContentError(f"scan has angle_increment {msg.angle_increment}", topic=topic)
    if abs(ranges.shape[0] - expected) > _BEAM_COUNT_SLACK:
        raise LogContentError(
            f"scan ranges length {ranges.shape[0]} does not match the {expected} beams of "
            f"angle_min {msg.angle_min:.4f}, angle_max {msg.angle_max:.4f}, "
            f"angle_increment {msg.angle_increment:.6f}",
            topic=topic,
        )
    intensities = _first_echoes(msg.intensities) if multi else np.array(msg.intensities, dtype=np.float32)
    return Scan(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        log_time_ns=log_time_ns,
        frame_id=msg.header.frame_id.lstrip("/"),
        angle_min=float(msg.angle_min),
        angle_increment=float(msg.angle_increment),
        range_min=float(msg.range_min),
        range_max=float(msg.range_max),
        ranges=ranges,
        intensities=intensities if intensities.shape[0] == ranges.shape[0] else None,
        time_increment_s=float(getattr(msg, "time_increment", 0.0)),
    )


def _pose2d(header: Any, child: str, pose: Any, log_time_ns: int) -> Pose2D:
    q = pose.orientation
    return Pose2D(
        stamp_ns=stamp_to_ns(header.stamp),
        log_time_ns=log_time_ns,
        frame_id=header.frame_id.lstrip("/"),
        child_frame_id=child.lstrip("/"),
        x=float(pose.position.x),
        y=float(pose.position.y),
        yaw=yaw_from_quaternion(q.x, q.y, q.z, q.w),
    )


def decode_pose(msg: Any, msgtype: str, log_time_ns: int) -> Pose2D:
    """nav_msgs/Odometry, PoseStamped or PoseWithCovarianceStamped → planar :class:`Pose2D`."""
    if msgtype == ODOMETRY:
        t = msg.twist.twist
        return replace(_pose2d(msg.header, msg.child_frame_id, msg.pose.pose, log_time_ns), vx=float(t.linear.x),
                       vy=float(t.linear.y), wz=float(t.angular.z))
    if msgtype == POSE_COV_STAMPED:
        return _pose2d(msg.header, "", msg.pose.pose, log_time_ns)
    return _pose2d(msg.header, "", msg.pose, log_time_ns)


# Name tokens of Gazebo models that are the world around the robot, not the robot (ground_plane, turtlebot3_world,
# unit_box, ...), matched per token (a robot called boxer is no box).
_WORLD_MODEL_WORDS = frozenset({"ground", "plane", "world", "house", "building", "wall", "walls", "room", "door",
                                "table", "sun", "map", "office", "floor", "shelf", "box", "person", "actor", "unit",
                                "cylinder", "sphere", "obstacle", "cafe", "warehouse"})


def robot_model_index(names: Sequence[str], wanted: str | None) -> int | None:
    """Which of a gazebo_msgs/ModelStates' models is the robot: ``wanted`` (``topics.reference_model``), else
    the one model none of whose name's tokens is a world word (``_WORLD_MODEL_WORDS``); None when no single one
    is.

    Raises:
        LogContentError: ``wanted`` is not among the models.
    """
    if wanted is not None:
        if wanted not in names:
            raise LogContentError(f"ModelStates has no model {wanted!r} (topics.reference_model); it has "
                                  f"{', '.join(names)}")
        return list(names).index(wanted)
    robots = [i for i, n in enumerate(names)
              if not _WORLD_MODEL_WORDS & set(re.split(r"[_\-/.\s]+|(?<=[a-z])(?=[0-9])", n.lower()))]
    return robots[0] if len(robots) == 1 else None


def decode_model_states(msg: Any, log_time_ns: int, wanted: str | None) -> Pose2D | None:
    """gazebo_msgs/ModelStates → the robot model's planar pose in Gazebo's world frame (None: no single model is
    the robot, :func:`robot_model_index`). The message has no header: the stamp is unset (0), and its log time
    stands in, on the scans' clock (recording.on_one_clock)."""
    names = [str(n) for n in msg.name]
    k = robot_model_index(names, wanted)
    if k is None:
        return None
    pose = msg.pose[k]
    q = pose.orientation
    return Pose2D(stamp_ns=0, log_time_ns=log_time_ns, frame_id="", child_frame_id=names[k],
                  x=float(pose.position.x), y=float(pose.position.y), yaw=yaw_from_quaternion(q.x, q.y, q.z, q.w))


def decode_transforms(msg: Any, static: bool, log_time_ns: int = 0) -> Iterator[Transform]:
    """tf2_msgs/TFMessage → one :class:`Transform` per TransformStamped."""
    for ts in msg.transforms:
        t, r = ts.transform.translation, ts.transform.rotation
        quat = np.array([r.x, r.y, r.z, r.w], dtype=np.float64)
        norm = float(np.linalg.norm(quat))
        yield Transform(
            stamp_ns=stamp_to_ns(ts.header.stamp),
            parent=ts.header.frame_id.lstrip("/"),
            child=ts.child_frame_id.lstrip("/"),
            translation=np.array([t.x, t.y, t.z], dtype=np.float64),
            rotation_xyzw=quat / norm if norm > 0 else np.array([0.0, 0.0, 0.0, 1.0]),
            static=static,
            log_time_ns=log_time_ns,
        )


_PC2_DTYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 8: "f8"}


def decode_pointcloud_colors(msg: Any, log_time_ns: int, topic: str) -> BeamColors:
    """sensor_msgs/PointCloud2 with x, y, z and rgb (packed float32 or uint32) → :class:`BeamColors`.

    Raises:
        LogContentError: the cloud has no x, y, z or no rgb/rgba field.
    """
    fields = {f.name: f for f in msg.fields}
    missing = [n for n in ("x", "y", "z") if n not in fields]
    color_name = "rgb" if "rgb" in fields else ("rgba" if "rgba" in fields else None)
    if missing or color_name is None:
        raise LogContentError(
            f"PointCloud2 lacks fields {missing + ([] if color_name else ['rgb'])} needed for beam colors",
            topic=topic,
        )
    endian = ">" if msg.is_bigendian else "<"
    names = ["x", "y", "z", color_name]
    dtype = np.dtype(
        {
            "names": names,
            "formats": [endian + ("u4" if n == color_name else _PC2_DTYPES[fields[n].datatype]) for n in names],
            "offsets": [fields[n].offset for n in names],
            "itemsize": msg.point_step,
        }
    )
    count = msg.width * msg.height
    data = np.asarray(msg.data, dtype=np.uint8)
    if msg.row_step * msg.height != data.shape[0] or msg.point_step * msg.width > msg.row_step:
        raise LogContentError("PointCloud2 data size does not match its width and steps", topic=topic)
    rows = data.reshape(msg.height, msg.row_step)[:, : msg.point_step * msg.width]
    cloud = np.frombuffer(np.ascontiguousarray(rows).tobytes(), dtype=dtype, count=count)
    packed = cloud[color_name].astype(np.uint32)
    rgb = np.stack([(packed >> 16) & 0xFF, (packed >> 8) & 0xFF, packed & 0xFF], axis=1).astype(np.uint8)
    points = np.stack([cloud["x"], cloud["y"], cloud["z"]], axis=1).astype(np.float32)
    return BeamColors(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        log_time_ns=log_time_ns,
        frame_id=msg.header.frame_id.lstrip("/"),
        points=points,
        rgb=rgb,
    )


# 8-bit Bayer mosaics and packed YUV: bytes per pixel and the OpenCV conversion to RGB. OpenCV names a Bayer
# pattern by the 2x2 block's second row (its RG is ROS's bayer_bggr8), hence the apparent swap.
_TO_RGB = {
    "bayer_rggb8": (1, cv2.COLOR_BayerBG2RGB),
    "bayer_bggr8": (1, cv2.COLOR_BayerRG2RGB),
    "bayer_gbrg8": (1, cv2.COLOR_BayerGR2RGB),
    "bayer_grbg8": (1, cv2.COLOR_BayerGB2RGB),
    "yuv422": (2, cv2.COLOR_YUV2RGB_UYVY),  # ROS yuv422 is UYVY
    "uyvy": (2, cv2.COLOR_YUV2RGB_UYVY),
    "yuv422_yuy2": (2, cv2.COLOR_YUV2RGB_YUY2),
    "yuyv": (2, cv2.COLOR_YUV2RGB_YUY2),
}


def _raw_pixels(msg: Any, data: npt.NDArray[np.uint8], topic: str) -> tuple[npt.NDArray[np.uint8], str]:
    """A raw sensor_msgs/Image's pixels as RGB (or mono8), and that encoding."""
    if msg.encoding in _TO_RGB:  # raw sensor layouts (sensor_msgs/image_encodings), converted as cv_bridge does
        cells, code = _TO_RGB[msg.encoding]
        rows = data.reshape(msg.height, msg.step)[:, : msg.width * cells]
        return np.asarray(cv2.cvtColor(rows.reshape(msg.height, msg.width, cells) if cells > 1 else rows, code),
                          dtype=np.uint8), "rgb8"
    encoding = msg.encoding
    channels = {"mono8": 1, "8UC1": 1, "rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "8UC3": 3}
    if encoding not in channels:
        raise LogContentError(f"image encoding {encoding!r} is not supported", topic=topic)
    c = channels[encoding]
    rows = data.reshape(msg.height, msg.step)[:, : msg.width * c]
    pixels = rows.reshape(msg.height, msg.width, c) if c > 1 else rows.reshape(msg.height, msg.width)
    if encoding in ("bgr8", "8UC3"):
        pixels = pixels[:, :, ::-1]
    elif encoding == "rgba8":
        pixels = pixels[:, :, :3]
    elif encoding == "bgra8":
        pixels = pixels[:, :, 2::-1]
    return np.ascontiguousarray(pixels), "mono8" if c == 1 else "rgb8"


def decode_image(msg: Any, msgtype: str, log_time_ns: int, topic: str) -> Image:
    """sensor_msgs/Image (mono8, rgb8, bgr8, rgba8, bgra8, 8-bit Bayer, yuv422/uyvy, yuyv) or CompressedImage →
    RGB or mono array.

    Raises:
        LogContentError: an encoding we do not read, data that does not fit the image's size, or a compressed
            image OpenCV cannot decode.
    """
    data = np.asarray(msg.data, dtype=np.uint8)
    if msgtype == COMPRESSED_IMAGE:
        decoded = cv2.imdecode(data, cv2.IMREAD_COLOR)
        if decoded is None:
            raise LogContentError(f"cannot decode compressed image ({msg.format})", topic=topic)
        pixels = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)
        encoding = "rgb8"
    else:
        try:
            pixels, encoding = _raw_pixels(msg, data, topic)
        except (ValueError, cv2.error) as err:  # data shorter than height × step, or a size OpenCV refuses
            raise LogContentError(f"{msg.encoding} image data ({data.size} bytes) does not fit {msg.width}×"
                                  f"{msg.height} at step {msg.step}: {' '.join(str(err).split())}",
                                  topic=topic) from err
    return Image(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        log_time_ns=log_time_ns,
        frame_id=msg.header.frame_id.lstrip("/"),
        pixels=np.asarray(pixels, dtype=np.uint8),
        encoding=encoding,
    )


def decode_camera_info(msg: Any, log_time_ns: int) -> CameraInfo:
    """sensor_msgs/CameraInfo (ROS 1 ``K``/``D``/``P`` or ROS 2 ``k``/``d``/``p``) → :class:`CameraInfo` of the
    images as published. K, P, width and height describe the full-resolution sensor; with a region of interest
    (``roi``) and binning (``binning_x/y`` > 1) the image pixels are (full − roi offset) / binning, so the
    intrinsics are shifted and scaled the same way (CameraInfo message documentation)."""
    k = getattr(msg, "k", None)
    k = np.asarray(k if k is not None else msg.K, dtype=np.float64).reshape(3, 3)
    d = getattr(msg, "d", None)
    d = d if d is not None else msg.D
    p = getattr(msg, "p", None)
    p = np.asarray(p if p is not None else msg.P, dtype=np.float64).reshape(3, 4)
    width, height = int(msg.width), int(msg.height)
    roi = getattr(msg, "roi", None)
    x0, y0 = (int(roi.x_offset), int(roi.y_offset)) if roi is not None and roi.width and roi.height else (0, 0)
    if roi is not None and roi.width and roi.height:
        width, height = int(roi.width), int(roi.height)
    bx, by = max(int(getattr(msg, "binning_x", 0)), 1), max(int(getattr(msg, "binning_y", 0)), 1)
    if (x0, y0, bx, by) != (0, 0, 1, 1):
        to_image = np.array([[1.0 / bx, 0.0, -x0 / bx], [0.0, 1.0 / by, -y0 / by], [0.0, 0.0, 1.0]])
        k, p = to_image @ k, to_image @ p
        width, height = width // bx, height // by
    return CameraInfo(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        log_time_ns=log_time_ns,
        frame_id=msg.header.frame_id.lstrip("/"),
        width=width,
        height=height,
        distortion_model=str(msg.distortion_model),
        d=np.asarray(d, dtype=np.float64),
        k=k,
        p=p,
    )


# ROS 1 vision_msgs carries integer class ids; doorbatch writes and reads them as indices of this list.
ROS1_CLASS_NAMES = ("door", "handle")


def ros1_class_id(name: str) -> int:
    """The ROS 1 integer class id doorbatch writes for a class name: its index in :data:`ROS1_CLASS_NAMES`
    (the default ``doorpose.class_names``, which reads it back), a number as it is."""
    return ROS1_CLASS_NAMES.index(name) if name in ROS1_CLASS_NAMES else int(name)


def _detection(det: Any) -> Detection:
    """One box with its best hypothesis. The class id is kept as the log gives it, as text: Humble's
    ``hypothesis.class_id``, Foxy's string ``id``, Noetic's int64 ``id`` ("0"); a numeric id is an index
    into the detector's label list (``doorpose.class_names``), resolved where the classes are used."""
    best_id, best_score = "", 0.0
    for hyp in det.results:
        inner = getattr(hyp, "hypothesis", None)  # ROS 2 Galactic on: results[i].hypothesis.class_id
        class_id = str(inner.class_id if inner is not None else hyp.id)
        score = float(inner.score if inner is not None else hyp.score)
        if score >= best_score:
            best_id, best_score = class_id, score
    center = det.bbox.center
    position = getattr(center, "position", None)  # ROS 2 vision_msgs/Pose2D has position.x/y
    cx, cy = (position.x, position.y) if position is not None else (center.x, center.y)
    return Detection(
        class_id=best_id,
        score=best_score,
        center_x=float(cx),
        center_y=float(cy),
        size_x=float(det.bbox.size_x),
        size_y=float(det.bbox.size_y),
    )


def decode_detections(msg: Any, log_time_ns: int) -> Detections:
    """vision_msgs/Detection2DArray (ROS 1 or ROS 2 layout) → :class:`Detections`."""
    return Detections(
        stamp_ns=stamp_to_ns(msg.header.stamp),
        log_time_ns=log_time_ns,
        frame_id=msg.header.frame_id.lstrip("/"),
        detections=tuple(_detection(d) for d in msg.detections),
    )


def decode(role: Role, msg: Any, msgtype: str, log_time_ns: int, topic: str, reference_model: str | None = None
           ) -> Iterator[Record]:
    """Decode one message of a topic with a known role into its records (TF gives several);
    ``reference_model``: the robot's model in a gazebo_msgs/ModelStates (None: :func:`robot_model_index`)."""
    if role is Role.SCAN:
        yield decode_scan(msg, log_time_ns, topic, msgtype)
    elif role is Role.REFERENCE and msgtype == MODEL_STATES:
        pose = decode_model_states(msg, log_time_ns, reference_model)
        if pose is not None:
            yield pose
    elif role in (Role.ODOMETRY, Role.REFERENCE):
        yield decode_pose(msg, msgtype, log_time_ns)
    elif role is Role.TRANSFORMS:
        yield from decode_transforms(msg, topic.rstrip("/").endswith("tf_static"), log_time_ns)
    elif role is Role.COLORS:
        yield decode_pointcloud_colors(msg, log_time_ns, topic)
    elif role is Role.IMAGE:
        yield decode_image(msg, msgtype, log_time_ns, topic)
    elif role is Role.CAMERA_INFO:
        yield decode_camera_info(msg, log_time_ns)
    elif role is Role.DETECTIONS:
        yield decode_detections(msg, log_time_ns)
