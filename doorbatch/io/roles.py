"""Which topic plays which role (DESIGN.md, Inputs): by message type, names tried first, config overrides."""

from __future__ import annotations

import difflib
from collections.abc import Mapping
from dataclasses import dataclass, field

from doorbatch.config import TopicsConfig
from doorbatch.errors import LogContentError
from doorbatch.io import decode as d
from doorbatch.records import Role


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One topic of a log: name, normalized message type (``pkg/msg/Name``), message count, encoding; ``schema``:
    the log's own type name where its messages are read as ``msgtype`` (a Foxglove schema,
    :mod:`~doorbatch.io.foxglove`), else empty."""

    name: str
    msgtype: str
    count: int
    encoding: str
    schema: str = ""


@dataclass(frozen=True)
class RoleAssignment:
    """The topic(s) chosen for each role and, per topic, why."""

    topics: dict[Role, tuple[str, ...]] = field(default_factory=dict)
    reasons: dict[str, str] = field(default_factory=dict)
    # Choices a user should hear of: a role detected among several topics whose others are not read.
    notes: list[str] = field(default_factory=list)

    def topic(self, role: Role) -> str | None:
        """The single topic of a role, or None."""
        chosen = self.topics.get(role, ())
        return chosen[0] if chosen else None

    def role_of(self) -> dict[str, Role]:
        """Topic → role, for every assigned topic."""
        return {t: role for role, names in self.topics.items() for t in names}


_TYPES: dict[Role, tuple[str, ...]] = {
    Role.SCAN: (d.LASERSCAN, d.MULTI_ECHO_LASERSCAN),
    Role.ODOMETRY: (d.ODOMETRY,),
    Role.REFERENCE: (d.ODOMETRY, d.POSE_STAMPED, d.POSE_COV_STAMPED, d.MODEL_STATES),
    Role.TRANSFORMS: (d.TF_MESSAGE, d.TF_MESSAGE_ROS1_LEGACY),
    Role.COLORS: (d.POINTCLOUD2,),
    Role.IMAGE: (d.IMAGE, d.COMPRESSED_IMAGE),
    Role.CAMERA_INFO: (d.CAMERA_INFO,),
    Role.DETECTIONS: (d.DETECTION2D_ARRAY,),
}

_NAMES: dict[Role, tuple[str, ...]] = {
    Role.SCAN: ("/scan", "/base_scan"),
    Role.ODOMETRY: ("/odom",),
    Role.REFERENCE: ("/ground_truth", "/gt", "/pose"),
    Role.TRANSFORMS: ("/tf", "/tf_static"),
    Role.COLORS: ("/scan_colors",),
    Role.IMAGE: ("/camera/image_raw", "/camera/image_raw/compressed"),
    Role.CAMERA_INFO: ("/camera/camera_info",),
    Role.DETECTIONS: ("/detections",),
}

# Words that mark an Odometry topic as a reference (ground truth / SLAM) rather than wheel odometry.
_REFERENCE_WORDS = ("truth", "gt", "reference", "slam", "amcl", "pose")
# Words that mark a pose topic as an operator's or a planner's input, never the robot's pose: RViz's
# /initialpose and /goal_pose, move_base's /move_base_simple/goal and /move_base/current_goal, waypoints.
_COMMAND_WORDS = ("goal", "initialpose", "initial", "target", "waypoint", "waypoints", "clicked", "setpoint", "cmd")


def _words(name: str) -> list[str]:
    return name.lower().replace("-", "_").replace("/", "_").split("_")


def _looks_like_reference(name: str) -> bool:
    return any(w in _REFERENCE_WORDS for w in _words(name))


def _looks_like_command(name: str) -> bool:
    return any(w in _COMMAND_WORDS for w in _words(name))


def is_initial_pose_topic(name: str) -> bool:
    """Whether a pose topic is an operator's initial pose (RViz's /initialpose, ``initial_pose``), which a
    localizer takes anew on every message, rather than an estimate (/amcl_pose) whose first message is a start."""
    return any(w in ("initialpose", "initial") for w in _words(name))


# Lasers with at least this share of the busiest one's messages are as busy (two lasers at one rate, a few
# messages apart): among them the first name in sort order wins (stage_ros's /base_scan_0, its first laser).
_AS_BUSY_SHARE = 0.9


def _pick(role: Role, candidates: list[TopicInfo]) -> tuple[TopicInfo, str] | None:
    """The preferred topic among candidates of the right type: a name tried first, else the busiest; among lasers
    about as busy (``_AS_BUSY_SHARE``), the first by name."""
    if not candidates:
        return None
    by_name = {c.name: c for c in candidates}
    for name in _NAMES[role]:
        if name in by_name:
            return by_name[name], f"type {by_name[name].msgtype}, name {name} is tried first"
    most = max(c.count for c in candidates)
    busy = (sorted((c for c in candidates if c.count >= _AS_BUSY_SHARE * most), key=lambda c: c.name)
            if role is Role.SCAN else [max(candidates, key=lambda c: (c.count, c.name))])
    best = busy[0]
    why = f"type {best.msgtype}"
    if len(busy) > 1:
        why += f", first by name of {len(busy)} about as busy"
    elif len(candidates) > 1:
        why += f", most messages of {len(candidates)}"
    return best, why


def assign_roles(topics: Mapping[str, TopicInfo], overrides: TopicsConfig | None = None) -> RoleAssignment:
    """Choose the topic for each role.

    Raises:
        LogContentError: a topic named in the config is not in the log, or has a type that cannot
            play the role.
    """
    overrides = overrides or TopicsConfig()
    chosen: dict[Role, tuple[str, ...]] = {}
    reasons: dict[str, str] = {}

    for role in Role:
        wanted = getattr(overrides, role.value)
        if wanted is None:
            continue
        names = [wanted] if isinstance(wanted, str) else list(wanted)
        for name in names:
            info = topics.get(name)
            if info is None:
                fits = sorted(t.name for t in topics.values() if t.msgtype in _TYPES[role])
                close = difflib.get_close_matches(name, fits, n=1, cutoff=0.0)
                hint = (f"; did you mean {close[0]}? (its {role.value} topics: {', '.join(fits)})" if close
                        else f"; it has no topic of a {role.value} type")
                raise LogContentError(f"config topics.{role.value} names a topic the log does not have{hint}",
                                      topic=name)
            if info.msgtype not in _TYPES[role]:
                raise LogContentError(
                    f"config topics.{role.value}: type {info.msgtype} cannot be the {role.value} role",
                    topic=name,
                )
            reasons[name] = f"set by config topics.{role.value}"
        chosen[role] = tuple(names)

    taken = {n for names in chosen.values() for n in names}
    notes: list[str] = []

    def free(role: Role) -> list[TopicInfo]:
        return [t for t in topics.values() if t.msgtype in _TYPES[role] and t.name not in taken]

    # Reference first among the pose roles, so that /ground_truth never becomes odometry.
    if Role.REFERENCE not in chosen:
        refs = [
            t
            for t in free(Role.REFERENCE)
            if (t.name in _NAMES[Role.REFERENCE] or t.msgtype != d.ODOMETRY or _looks_like_reference(t.name))
            and not _looks_like_command(t.name)
        ]
        refs = [t for t in refs if t.name not in _NAMES[Role.ODOMETRY]]
        if any(t.msgtype != d.MODEL_STATES for t in refs):  # a header-stamped pose topic wins over Gazebo's states
            refs = [t for t in refs if t.msgtype != d.MODEL_STATES]
        pick = _pick(Role.REFERENCE, refs)
        if pick:
            chosen[Role.REFERENCE] = (pick[0].name,)
            reasons[pick[0].name] = pick[1]
            taken.add(pick[0].name)

    for role in Role:
        if role in chosen or role is Role.REFERENCE:
            continue
        if role is Role.TRANSFORMS:
            tfs = sorted(t.name for t in free(role))
            if tfs:
                chosen[role] = tuple(tfs)
                for name in tfs:
                    kind = "static" if name.rstrip("/").endswith("tf_static") else "dynamic"
                    reasons[name] = f"type {topics[name].msgtype} ({kind} transforms)"
                taken.update(tfs)
            continue
        candidates = free(role)
        pick = _pick(role, candidates)
        if pick:
            chosen[role] = (pick[0].name,)
            reasons[pick[0].name] = pick[1]
            taken.add(pick[0].name)
            others = sorted(c.name for c in candidates if c is not pick[0])
            if role is Role.SCAN and others:
                notes.append(f"{len(candidates)} laser scan topics: {pick[0].name} is read ({pick[1]}), "
                             f"{', '.join(others)} not (one laser per run; topics.scan chooses)")
            elif role is Role.ODOMETRY and (others := [o for o in others if not _looks_like_reference(o)]):
                # wheel odometry beside a fused one (an EKF's, with an IMU heading); a second truth topic is none
                notes.append(f"{len(others) + 1} odometry topics: {pick[0].name} is read ({pick[1]}), "
                             f"{', '.join(others)} not; topics.odometry chooses (a fused odometry, e.g. "
                             "robot_localization's /odometry/filtered, is often the better motion input)")
    return RoleAssignment(topics=chosen, reasons=reasons, notes=notes)
