"""rosbags typestores with the message definitions the default stores lack.

DESIGN.md, Known pitfalls: the ROS 1 Noetic store lacks ``tf2_msgs/TFMessage`` and no default store has
``vision_msgs``. We register them from ``.msg`` text (ROS 2 Humble's vision_msgs 4.x layout for ROS 2, and
Noetic's vision_msgs 1.x layout for ROS 1), parsed by rosbags itself.
"""

from __future__ import annotations

from functools import cache

from rosbags.interfaces.typing import Typesdict
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

_VISION_ROS2 = {
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
}

_VISION_ROS1 = {
    "vision_msgs/msg/BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "int64 id\nfloat64 score\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\nsensor_msgs/Image source_img\n"
    ),
    "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
}

_TF2_ROS1 = {"tf2_msgs/msg/TFMessage": "geometry_msgs/TransformStamped[] transforms\n"}


def _register(store: Typestore, defs: dict[str, str]) -> None:
    for name, text in defs.items():
        if name not in store.types:
            store.register(get_types_from_msg(text, name))


@cache
def ros2_typestore() -> Typestore:
    """ROS 2 Humble types plus vision_msgs; what doorbatch writes (CDR) is described by this store."""
    return new_ros2_typestore()


def new_ros2_typestore() -> Typestore:
    """A fresh store of :func:`ros2_typestore`'s types, for a writer that registers more (ROS 1-only types)."""
    store = get_typestore(Stores.ROS2_HUMBLE)
    _register(store, _VISION_ROS2)
    return store


def register_ros1_type(target: Typestore, source: Typestore, msgtype: str) -> None:
    """Register a type that only ROS 1 knows (``tf/tfMessage``, a robot's own messages) into a ROS 2 store,
    from its ROS 1 definition; the types it uses that the store has (``std_msgs/Header``, ...) keep their ROS 2
    layout, so ``migrate_message`` moves a message into it as into any ROS 2 type."""
    text, _ = source.generate_msgdef(msgtype, ros_version=1)
    target.register({k: v for k, v in get_types_from_msg(text, msgtype).items() if k not in target.types})


@cache
def ros1_typestore() -> Typestore:
    """ROS 1 Noetic types plus tf2_msgs/TFMessage and vision_msgs (for bags without definitions)."""
    store = get_typestore(Stores.ROS1_NOETIC)
    _register(store, _TF2_ROS1)
    _register(store, _VISION_ROS1)
    return store


def normalize_msgtype(name: str) -> str:
    """``sensor_msgs/LaserScan`` or ``sensor_msgs/msg/LaserScan`` → ``sensor_msgs/msg/LaserScan``."""
    parts = name.strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return name.strip()


# MCAP schema encodings whose text is OMG IDL (rosbag2 writes ros2idl for types defined in .idl files).
IDL_SCHEMA_ENCODINGS = frozenset({"ros2idl", "omgidl"})
_IDL_SEPARATOR = "=" * 80 + "\n"


def types_from_schema(text: str, name: str, encoding: str) -> Typesdict:
    """The types a channel's schema defines: ``.msg`` text (``ros2msg``, ``ros1msg``) or IDL (``ros2idl``:
    the type's IDL and its dependencies', each after an ``IDL: pkg/msg/Type`` line between lines of 80 '=')."""
    if encoding not in IDL_SCHEMA_ENCODINGS:
        return get_types_from_msg(text, name)
    types: Typesdict = {}
    for part in (text.split(_IDL_SEPARATOR)[1:] if text.startswith(f"{_IDL_SEPARATOR}IDL: ") else [text]):
        types.update(get_types_from_idl(part.split("\n", 1)[1] if part.startswith("IDL: ") else part))
    return types
