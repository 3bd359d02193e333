"""Foxglove's message schemas read as the ROS 2 messages they stand for.

Logs written without ROS, by the Foxglove SDK or by hand with ``mcap``, carry Foxglove's own schemas
(https://docs.foxglove.dev/docs/visualization/message-schemas): ``foxglove.LaserScan``, ``foxglove.FrameTransform``
and so on, encoded as protobuf (the SDK's choice) or JSON; ROS logs recorded through a Foxglove bridge carry the
same schemas as ``foxglove_msgs/msg/...`` in CDR or ROS 1. Each message becomes the ROS 2 message (rosbags' class
of :func:`~doorbatch.io.typestore.ros2_typestore`) that plays its role, so that roles, decoding, ``convert`` and the
annotated MCAP treat it as any ROS log's:

=====================  ==================================  ==============================================
Foxglove schema        ROS 2 message                       notes
=====================  ==================================  ==============================================
LaserScan              sensor_msgs/msg/LaserScan           see :func:`laser_scan`
Odometry               nav_msgs/msg/Odometry               planar: x, y, yaw of ``pose``, its covariance
PoseInFrame            geometry_msgs/msg/PoseStamped       planar
FrameTransform(s)      tf2_msgs/msg/TFMessage              every transform, 3D
CompressedImage        sensor_msgs/msg/CompressedImage
RawImage               sensor_msgs/msg/Image
CameraCalibration      sensor_msgs/msg/CameraInfo          D, K, R, P as given
=====================  ==================================  ==============================================

One message reaches us in three shapes: a protobuf message (``timestamp.seconds``/``nanos``, ``bytes``), a JSON
object (``timestamp.sec``/``nsec``, bytes as base64 text) or a rosbags object (``timestamp.sec``/``nanosec``,
``uint8`` arrays); the accessors below read all three.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from mcap.records import Schema

from doorbatch.errors import LogContentError, LogReadError
from doorbatch.geometry.rotations import quaternion_to_matrix
from doorbatch.io import ros_messages as rm
from doorbatch.io.decode import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    LASERSCAN,
    ODOMETRY,
    POSE_STAMPED,
    TF_MESSAGE,
    yaw_from_quaternion,
)
from doorbatch.io.roles import TopicInfo
from doorbatch.records import Transform

_ROS_TYPE = {
    "LaserScan": LASERSCAN,
    "Odometry": ODOMETRY,
    "PoseInFrame": POSE_STAMPED,
    "FrameTransform": TF_MESSAGE,
    "FrameTransforms": TF_MESSAGE,
    "CompressedImage": COMPRESSED_IMAGE,
    "RawImage": IMAGE,
    "CameraCalibration": CAMERA_INFO,
}
# The names a schema has in each encoding: protobuf, JSON and FlatBuffers ``foxglove.X``, ROS ``foxglove_msgs/msg/X``.
_PREFIXES = ("foxglove.", "foxglove_msgs/msg/")
# Round-off allowed in a scan origin: its offset (m) from the frame's origin, and 1 − |R_zz| (a tilt of
# √(2·1e-6) ≈ 1.4 mrad) out of the frame's xy-plane.
_PLANAR_TOLERANCE = 1e-6


def foxglove_kind(schema_name: str) -> str | None:
    """``LaserScan`` for ``foxglove.LaserScan`` or ``foxglove_msgs/msg/LaserScan`` (a name :func:`ros_type` knows),
    else None."""
    for prefix in _PREFIXES:
        if schema_name.startswith(prefix) and schema_name[len(prefix):] in _ROS_TYPE:
            return schema_name[len(prefix):]
    return None


def ros_type(schema_name: str) -> str | None:
    """The ROS 2 message type a Foxglove schema is read as (None: not one we read)."""
    kind = foxglove_kind(schema_name)
    return None if kind is None else _ROS_TYPE[kind]


def topic_info(topic: str, msgtype: str, count: int, encoding: str, readable: bool = True) -> TopicInfo:
    """A log's topic of type ``msgtype`` as the readers list it: a Foxglove schema we read (``readable``) under the ROS
    type its messages are read as, with the schema kept beside it (``TopicInfo.schema``); any other as it is."""
    shown = ros_type(msgtype) if readable else None
    return TopicInfo(topic, shown or msgtype, count, encoding, msgtype if shown else "")


def payload_decoder(schema: Schema, message_encoding: str) -> Callable[[bytes], Any]:
    """Bytes → the message of a protobuf or JSON channel: a protobuf message built by ``mcap-protobuf-support``
    from the schema's FileDescriptorSet, or the parsed JSON object.

    Raises:
        LogReadError: an encoding other than protobuf or JSON, or a schema the protobuf library cannot load.
    """
    if message_encoding == "json":
        return json.loads
    if message_encoding == "protobuf":
        from mcap_protobuf.decoder import DecoderFactory

        try:
            decoder = DecoderFactory().decoder_for(message_encoding, schema)
        except Exception as err:  # a FileDescriptorSet that does not parse or resolve
            raise LogReadError(f"cannot load the protobuf schema {schema.name} ({type(err).__name__}: {err})"
                               ) from err
        if decoder is None:
            raise LogReadError(f"channel of {schema.name} is protobuf but its schema is {schema.encoding!r}")
        return decoder
    raise LogReadError(f"{schema.name} messages in {message_encoding!r} encoding are not read (protobuf, JSON, "
                       "CDR and ROS 1 are)")


def _get(msg: Any, name: str, default: Any = None) -> Any:
    """Field ``name`` of a protobuf message, JSON object or rosbags message (``default`` where absent or null)."""
    value = msg.get(name) if isinstance(msg, dict) else getattr(msg, name, None)
    return default if value is None else value  # JSON's null is an absent field


def _stamp_ns(msg: Any) -> int:
    """The ``timestamp`` field in ns: protobuf ``seconds``/``nanos``, JSON ``sec``/``nsec``, ROS ``sec``/``nanosec``."""
    t = _get(msg, "timestamp")
    if t is None:
        return 0
    sec = _get(t, "sec", _get(t, "seconds", 0))
    nsec = _get(t, "nanosec", _get(t, "nsec", _get(t, "nanos", 0)))
    return int(sec) * 1_000_000_000 + int(nsec)


def _floats(values: Any) -> npt.NDArray[np.float64]:
    """A repeated number field as float64 (JSON writes non-finite numbers as null or as text such as "Infinity")."""
    if values is None:
        return np.zeros(0)
    if isinstance(values, list) and any(v is None or isinstance(v, str) for v in values):
        return np.array([math.nan if v is None else float(v) for v in values], dtype=np.float64)
    return np.asarray(values, dtype=np.float64).ravel()


def _bytes(values: Any) -> npt.NDArray[np.uint8]:
    """A bytes field: protobuf ``bytes``, JSON base64 text, or a ROS ``uint8`` array."""
    if values is None:
        return np.zeros(0, dtype=np.uint8)
    if isinstance(values, str):
        return np.frombuffer(base64.b64decode(values, validate=True), dtype=np.uint8)
    if isinstance(values, bytes | bytearray | memoryview):
        return np.frombuffer(bytes(values), dtype=np.uint8)
    return np.asarray(values, dtype=np.uint8).ravel()


def _xyz(v: Any) -> tuple[float, float, float]:
    return (float(_get(v, "x", 0.0)), float(_get(v, "y", 0.0)), float(_get(v, "z", 0.0)))


def _quaternion(q: Any) -> npt.NDArray[np.float64]:
    """(x, y, z, w) normalized; an unset quaternion (all zero, as protobuf leaves it) is the identity."""
    if q is None:
        return np.array([0.0, 0.0, 0.0, 1.0])
    xyzw = np.array([*_xyz(q), float(_get(q, "w", 0.0))])
    norm = float(np.linalg.norm(xyzw))
    return xyzw / norm if norm > 0.0 else np.array([0.0, 0.0, 0.0, 1.0])


def _planar(pose: Any) -> tuple[float, float, float]:
    """x, y, yaw of a ``foxglove.Pose`` (``position``, ``orientation``)."""
    x, y, _ = _xyz(_get(pose, "position"))
    q = _quaternion(_get(pose, "orientation"))
    return x, y, yaw_from_quaternion(*q)


def _frame(msg: Any, name: str = "frame_id") -> str:
    """A frame name field, without the leading "/" of ROS 1 names (as :mod:`doorbatch.io.decode` reads them)."""
    return str(_get(msg, name, "")).lstrip("/")


def origin_frame(frame_id: str, topic: str) -> str:
    """The frame doorbatch gives the origin of a topic's Foxglove scans where it lies off their frame's origin."""
    name = f"{topic.strip('/').replace('/', '_')}_origin"
    return f"{frame_id}/{name}" if frame_id else name


def _scan_origin(msg: Any, topic: str) -> tuple[npt.NDArray[np.float64], float, float]:
    """(offset (3,), heading φ, sign s) of a Foxglove scan's origin in its frame: a beam at angle a in the origin
    points at φ + s·a in the frame.

    Raises:
        LogContentError: an origin tilted out of the frame's xy-plane.
    """
    pose = _get(msg, "pose")  # absent: None, whose position and orientation read as absent too (the identity)
    offset = np.array(_xyz(_get(pose, "position")))
    rot = quaternion_to_matrix(_quaternion(_get(pose, "orientation")))
    if abs(abs(rot[2, 2]) - 1.0) > _PLANAR_TOLERANCE:
        raise LogContentError("foxglove.LaserScan whose origin is tilted out of its frame's xy-plane", topic=topic)
    return offset, math.atan2(rot[1, 0], rot[0, 0]), 1.0 if rot[2, 2] > 0.0 else -1.0


def scan_mount(msg: Any, topic: str) -> Transform | None:
    """The static transform from a Foxglove scan's frame to its origin (:func:`origin_frame`; the rotation is folded
    into the beam angles, :func:`laser_scan`), or None where the origin lies at the frame's origin (or where the
    message has no pose to read: :func:`as_ros_message` tells whether it reads at all). Taken from a topic's first
    readable scan, like a sensor mount (:meth:`~doorbatch.io.reader.LogReader.scan_origin_mounts`).

    Raises:
        Exception: a payload that does not decode (bad bytes or JSON), or an origin tilted out of the plane.
    """
    msg = _decoded(msg)
    offset, _, _ = _scan_origin(msg, topic)
    if float(np.abs(offset).max()) <= _PLANAR_TOLERANCE:
        return None
    frame = _frame(msg)
    return Transform(stamp_ns=0, parent=frame, child=origin_frame(frame, topic), translation=offset,
                     rotation_xyzw=np.array([0.0, 0.0, 0.0, 1.0]), static=True)


def laser_scan(msg: Any, topic: str, mount: Transform | None = None) -> Any:
    """``foxglove.LaserScan`` → sensor_msgs/LaserScan.

    Beam i of n lies at ``start_angle + i · (end_angle − start_angle) / (n − 1)`` about the z axis of ``pose``, the
    scan's origin in ``frame_id`` (Foxglove's schema). A rotation of that origin about z, upside down or not, is
    folded into the angles: a beam at angle a in the origin points at φ + s·a in the frame, φ the origin's heading
    and s = ±1 the sign of its z axis. An origin offset from the frame's origin is a mount: the scan is put in
    :func:`origin_frame`, which ``mount`` (:func:`scan_mount` of the topic's first readable scan) places in the
    frame. The schema states no range limits: range_min is 0 (a reading of 0, which drivers write for no echo, is
    then no hit, as in any log: :func:`~doorbatch.io.recording.usable_range_limits`) and range_max +inf, "not
    stated" (the recording takes the readings' no-return code where they show one,
    :func:`~doorbatch.io.recording.with_no_return_code`, else the localizers take
    ``localize.laser_max_range_fallback``).

    Raises:
        LogContentError: an origin tilted out of the frame's xy-plane, one offset other than ``mount`` (the
            topic's first readable scan's), or no ranges.
    """
    offset, heading, sign = _scan_origin(msg, topic)
    frame = _frame(msg)
    if float(np.abs(offset).max()) > _PLANAR_TOLERANCE:
        if mount is None or mount.parent != frame or not np.allclose(mount.translation, offset, rtol=0.0,
                                                                     atol=_PLANAR_TOLERANCE):
            held = ("none" if mount is None
                    else f"({', '.join(f'{v:.3f}' for v in mount.translation)}) in {mount.parent!r}")
            raise LogContentError(f"foxglove.LaserScan whose origin ({', '.join(f'{v:.3f}' for v in offset)}) m in "
                                  f"{frame!r} differs from the topic's first scan's ({held}): doorbatch reads a "
                                  "scan's origin as a fixed mount", topic=topic)
        frame = mount.child
    ranges = _floats(_get(msg, "ranges"))
    n = ranges.shape[0]
    if n == 0:
        raise LogContentError("foxglove.LaserScan with no ranges", topic=topic)
    start, end = float(_get(msg, "start_angle", 0.0)), float(_get(msg, "end_angle", 0.0))
    increment = (end - start) / (n - 1) if n > 1 else 1.0  # one beam: any increment describes it
    intensities = _floats(_get(msg, "intensities"))
    return rm.laser_scan(_stamp_ns(msg), frame, heading + sign * start, sign * increment, 0.0, math.inf,
                         ranges, intensities if intensities.shape[0] == n else None)


def _transform(msg: Any) -> Any:
    return rm.transform_stamped(_stamp_ns(msg), _frame(msg, "parent_frame_id"),
                                _frame(msg, "child_frame_id"), _xyz(_get(msg, "translation")),
                                _quaternion(_get(msg, "rotation")).tolist())


def as_ros(kind: str, msg: Any, topic: str, mount: Transform | None = None) -> Any:
    """The ROS 2 message of ``msg``, a Foxglove message of schema ``kind`` (:func:`foxglove_kind`).

    Raises:
        LogContentError: a message that has no ROS form (:func:`laser_scan`).
    """
    if kind == "LaserScan":
        return laser_scan(msg, topic, mount)
    if kind == "FrameTransform":
        return rm.tf_message([_transform(msg)])
    if kind == "FrameTransforms":
        return rm.tf_message([_transform(t) for t in _get(msg, "transforms", None) or []])
    stamp, frame = _stamp_ns(msg), _frame(msg)
    if kind == "Odometry":
        covariance = _floats(_get(msg, "pose_covariance"))
        return rm.odometry(stamp, frame, _frame(msg, "body_frame_id"), *_planar(_get(msg, "pose")),
                           covariance=covariance if covariance.shape[0] == 36 else None)
    if kind == "PoseInFrame":
        return rm.pose_stamped(stamp, frame, *_planar(_get(msg, "pose")))
    if kind == "CompressedImage":
        return rm.compressed_image(stamp, frame, str(_get(msg, "format", "")), _bytes(_get(msg, "data")))
    if kind == "RawImage":
        return rm.image(stamp, frame, int(_get(msg, "width", 0)), int(_get(msg, "height", 0)),
                        str(_get(msg, "encoding", "")), int(_get(msg, "step", 0)), _bytes(_get(msg, "data")))
    if kind == "CameraCalibration":
        k, p, r, d = (_floats(_get(msg, name, _get(msg, name.lower()))) for name in ("K", "P", "R", "D"))
        if k.shape[0] != 9:
            raise LogContentError(f"foxglove.CameraCalibration with {k.shape[0]} values of K, not 9", topic=topic)
        return rm.camera_info(stamp, frame, int(_get(msg, "width", 0)), int(_get(msg, "height", 0)), k,
                              d, str(_get(msg, "distortion_model", "")),
                              p=p if p.shape[0] == 12 else None, r=r if r.shape[0] == 9 else None)
    raise ValueError(f"not a Foxglove schema doorbatch reads: {kind}")


@dataclass(frozen=True, slots=True)
class Payload:
    """A protobuf or JSON message not decoded yet: its channel's decoder (:func:`payload_decoder`) and its bytes."""

    decode: Callable[[bytes], Any]
    data: bytes


def _decoded(msg: Any) -> Any:
    """A :class:`Payload` decoded; any other message as it is."""
    return msg.decode(msg.data) if isinstance(msg, Payload) else msg


def as_ros_message(kind: str, msg: Any, topic: str, mount: Transform | None = None) -> tuple[str, Any]:
    """(ROS 2 message type, ROS 2 message) of one Foxglove message of schema ``kind``: a rosbags object of
    ``foxglove_msgs``, or a :class:`Payload` decoded here (:func:`as_ros`; ``mount``: its topic's
    :func:`scan_mount`).

    Raises:
        LogContentError: a message that does not decode, is not an object, or has no ROS form.
    """
    try:
        msg = _decoded(msg)
        if isinstance(msg, list | str | int | float | bool) or msg is None:  # JSON that is not an object
            raise LogContentError(f"foxglove.{kind} message is JSON {type(msg).__name__}, not an object", topic=topic)
        return _ROS_TYPE[kind], as_ros(kind, msg, topic, mount)
    except LogContentError:
        raise
    except Exception as err:  # bad JSON, protobuf bytes, base64, or field values of the wrong kind
        raise LogContentError(f"unreadable foxglove.{kind} message ({type(err).__name__}: {err})",
                              topic=topic) from err
