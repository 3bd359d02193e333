"""A log's pose topic as the start of a localization, or as another localizer's trajectory.

``doorbatch localize --init /initialpose``: Nav2 AMCL starts from the ``/initialpose`` an operator sets in RViz
(geometry_msgs/PoseWithCovarianceStamped, with its covariance) and does nothing with the scans before it. The
first message of the named topic gives the start pose, its time and, where the message carries one, its
covariance (:func:`read_start_pose`). Any pose type the reader decodes works (Odometry, PoseStamped,
PoseWithCovarianceStamped), so ``--init /amcl_pose`` starts where AMCL's first estimate was.

``doorbatch evaluate LOG:/amcl_pose``: every message of a pose topic, as a trajectory
(:func:`read_pose_topic`), so that the AMCL that ran in a recorded session is scored beside doorbatch's runs.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.errors import UsageError
from doorbatch.io.decode import ODOMETRY, POSE_COV_STAMPED, POSE_STAMPED, decode_pose
from doorbatch.io.reader import open_log
from doorbatch.io.roles import TopicInfo

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
POSE_TYPES = (POSE_COV_STAMPED, POSE_STAMPED, ODOMETRY)


@dataclass(frozen=True)
class StartPose:
    """The first pose of a topic: where and when to start, and how sure the message was.

    Attributes:
        topic: the topic it came from.
        stamp_ns: the message's header stamp (scans before it are not localized).
        log_time_ns: when the log recorded it (the start's time where the stamp is on another clock: RViz
            stamps with wall time while a simulation's scans carry sim time).
        pose: (3,) x, y, yaw in the message's frame.
        frame_id: that frame.
        sigma: (3,) standard deviations of x, y, yaw from the message's covariance; None where it has none
            (PoseStamped) or it is not positive on those three axes.
    """

    topic: str
    stamp_ns: int
    log_time_ns: int
    pose: FloatArray
    frame_id: str
    sigma: FloatArray | None


def _sigma(msg: object, msgtype: str) -> FloatArray | None:
    """√ of the x, y and yaw variances of a 6×6 pose covariance (row-major x y z roll pitch yaw)."""
    if msgtype == POSE_STAMPED:
        return None
    cov = np.asarray(msg.pose.covariance, dtype=np.float64).reshape(-1)  # type: ignore[attr-defined]
    if cov.size != 36:
        return None
    var = cov[[0, 7, 35]]
    return np.sqrt(var) if bool(np.all(np.isfinite(var)) and np.all(var > 0.0)) else None


def _check_pose_topic(topics: Mapping[str, TopicInfo], topic: str, path: Path, asked: str) -> None:
    """Raise a :class:`UsageError` naming the log's pose topics unless ``topic`` is one (``asked``: the option)."""
    poses = sorted(t for t, info in topics.items() if info.msgtype in POSE_TYPES)
    listed = f"pose topics in the log: {', '.join(poses) or 'none'}"
    if topic not in topics:
        raise UsageError(f"{asked} {topic}: no such topic in {path.name} ({listed})")
    if topics[topic].msgtype not in POSE_TYPES:
        raise UsageError(f"{asked} {topic}: a {topics[topic].msgtype}, not a pose ({listed})")


def read_start_poses(path: Path, topic: str) -> list[StartPose]:
    """Every message of ``topic`` in the log at ``path``, in log order: the first is the start; AMCL re-initializes
    its filter on each later one (an operator setting the pose again in RViz after the robot got lost).

    Raises:
        UsageError: the log has no such topic, it is not a pose type, or it has no message.
    """
    with open_log(path) as reader:
        _check_pose_topic(reader.topics, topic, path, "--init")
        starts = []
        for raw in reader.raw_messages([topic]):
            p = decode_pose(raw.msg, raw.msgtype, raw.log_time_ns)
            starts.append(StartPose(topic, p.stamp_ns, raw.log_time_ns, np.array([p.x, p.y, p.yaw]), p.frame_id,
                                    _sigma(raw.msg, raw.msgtype)))
    if not starts:
        raise UsageError(f"--init {topic}: the topic has no message in {path.name}")
    return starts


def read_start_pose(path: Path, topic: str) -> StartPose:
    """The first message of ``topic`` in the log at ``path`` (:func:`read_start_poses`).

    Raises:
        UsageError: the log has no such topic, it is not a pose type, or it has no message.
    """
    return read_start_poses(path, topic)[0]


def read_pose_topic(path: Path, topic: str) -> tuple[npt.NDArray[np.int64], FloatArray]:
    """Every pose of ``topic`` in the log at ``path``: stamps (N,) in header time, sorted, and (N, 3) x, y, yaw.

    Raises:
        UsageError: the log has no such topic, it is not a pose type, or it has no message.
    """
    with open_log(path) as reader:
        _check_pose_topic(reader.topics, topic, path, "evaluate")
        poses = [decode_pose(raw.msg, raw.msgtype, raw.log_time_ns) for raw in reader.raw_messages([topic])]
    if not poses:
        raise UsageError(f"evaluate {topic}: the topic has no message in {path.name}")
    stamps = np.array([p.stamp_ns for p in poses], dtype=np.int64)
    order = np.argsort(stamps, kind="stable")
    return stamps[order], np.array([[p.x, p.y, p.yaw] for p in poses])[order]
