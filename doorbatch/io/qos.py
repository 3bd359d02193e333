"""The QoS a log records its publishers offered (rosbag2's ``offered_qos_profiles``), which ``ros2 bag play`` replays.

A copy of a log (``doorbatch convert``, ``split``, annotated.mcap) keeps the input's profiles where the input records
them: a ROS 2 bag's metadata, an MCAP channel's ``offered_qos_profiles`` metadata, a ROS 1 bag connection's
``latching`` flag. Where it does not, :func:`default_qos` chooses by topic name.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2.metadata import parse_qos

# Topics published once and latched in ROS: a player must hand their message to late subscribers.
LATCHED_TOPICS = ("/map", "/doorbatch/map")
_FOREVER = QosTime(2147483647, 4294967295)  # rclcpp's "infinite" duration, as rosbag2 records it


def _profile(latched: bool) -> Qos:
    """Reliable; transient local with depth 1 when ``latched``, else volatile with depth 10."""
    return Qos(QosHistory.KEEP_LAST, 1 if latched else 10, QosReliability.RELIABLE,
               QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, _FOREVER, _FOREVER,
               QosLiveliness.AUTOMATIC, _FOREVER, False)


def default_qos(topic: str) -> Qos:
    """The profile for a topic whose log records none: transient local (latched) for /tf_static and
    :data:`LATCHED_TOPICS`, else volatile."""
    return _profile(topic.rstrip("/").endswith("tf_static") or topic in LATCHED_TOPICS)


def ros1_latched_qos(latching: int | str | None) -> list[Qos]:
    """A ROS 1 connection's ``latching`` header as profiles: latched → one transient local profile; else none
    recorded (ROS 1 has no other QoS)."""
    return [_profile(True)] if str(latching or "0") == "1" else []


def mcap_channel_qos(metadata: Mapping[str, str]) -> list[Qos]:
    """The profiles an MCAP channel's ``offered_qos_profiles`` metadata holds (as ``ros2 bag record -s mcap``
    writes it), or its ROS 1 ``latching`` ("true"/"1", as the ros1 profile records it); none where it says neither
    (a copy then chooses by topic name)."""
    if "offered_qos_profiles" not in metadata and "latching" in metadata:
        return ros1_latched_qos(1 if str(metadata["latching"]).lower() in ("1", "true") else 0)
    text = metadata.get("offered_qos_profiles", "")
    try:
        return list(parse_qos(text)) if text.strip() else []
    except Exception:  # rosbags' ReaderError, or YAML of another shape: the input says nothing usable
        return []


def is_latched(profiles: Sequence[Qos]) -> bool:
    """Whether a publisher with these profiles hands its last message to late subscribers (transient local)."""
    return any(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles)
