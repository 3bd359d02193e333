"""What ``doorbatch doorpose`` reads from a log: TF, camera intrinsics, scans, robot poses, and door boxes
(from a vision_msgs/Detection2DArray topic, or by running a detector over the log's images as they stream,
so that no log of images is ever held in memory)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import LogContentError
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.io.decode import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    decode_camera_info,
    decode_image,
    stamp_to_ns,
)
from doorbatch.io.log_clock import LogClock
from doorbatch.io.reader import LogReader, RawMessage, open_log
from doorbatch.io.recording import (
    PoseSeries,
    odometry_poses,
    read_transforms,
    resolve_base_frame,
    robot_pose_series,
    scans_clock,
    unset_stamps,
)
from doorbatch.records import CameraInfo, Detection, Detections, Image, Pose2D, Role, Scan

ImageDetector = Callable[[Image], tuple[Detection, ...]]


@dataclass
class DoorPoseInputs:
    """A log's inputs to the door pose stage. Scans and detections are sorted by stamp."""

    path: str
    tf: TfBuffer
    camera_info: CameraInfo
    scans: list[Scan]
    detections: list[Detections]
    reference: PoseSeries | None
    odometry: PoseSeries | None
    warnings: list[str] = field(default_factory=list)
    base_link: str = "base_link"  # the robot's base frame in this log's TF tree (recording.resolve_base_frame)
    log_clock: LogClock = field(default_factory=LogClock)  # the recorder's clock against the scans' stamps


def read_doorpose_inputs(path: Path, config: DoorbatchConfig, detector: ImageDetector | None = None
                         ) -> DoorPoseInputs:
    """Read the log for TF, then for the rest; with ``detector`` the images are run through it one by one, else
    the detections topic is read (and, where the log has images, their stamps: :func:`_on_image_stamps`).

    Raises:
        LogContentError: no scan, no camera_info, or no detections topic (and no detector).
        LogReadError: the log cannot be read.
    """
    box_role = Role.IMAGE if detector is not None else Role.DETECTIONS
    roles = [Role.SCAN, Role.ODOMETRY, Role.REFERENCE, Role.CAMERA_INFO, box_role]
    scans: list[Scan] = []
    odom: list[Pose2D] = []
    ref: list[Pose2D] = []
    boxes: list[Detections] = []
    info: CameraInfo | None = None
    with open_log(path, config) as reader:
        tf = read_transforms(reader, config)
        for role, what in ((Role.SCAN, "a sensor_msgs/LaserScan topic"),
                           (Role.CAMERA_INFO, "a sensor_msgs/CameraInfo topic (the camera intrinsics)"),
                           (box_role, "an image topic for --detector" if detector is not None else
                            "a vision_msgs/Detection2DArray topic (or give --detector MODEL)")):
            if reader.roles.topic(role) is None:
                raise LogContentError(f"doorpose needs {what}", path=path)
        image_topic = _colour_image_topic(reader, config) if detector is not None else None
        box_topic = image_topic or reader.roles.topic(box_role)
        info_topic, note = _camera_info_of_boxes(reader, box_topic, config)
        info_name = info_topic or reader.roles.topic(Role.CAMERA_INFO)  # named where it holds no message
        warnings_pre = [note] if note else []
        detections: list[Detections] = []  # from the detections topic, before their stamps are checked
        first_info = _first_message(reader, info_topic) if info_topic is not None else None
        if first_info is not None:
            info = decode_camera_info(first_info.msg, first_info.log_time_ns)
        if image_topic is not None and detector is not None:
            for raw in reader.raw_messages([image_topic]):
                image = decode_image(raw.msg, raw.msgtype, raw.log_time_ns, raw.topic)
                boxes.append(Detections(image.stamp_ns, image.log_time_ns, image.frame_id, detector(image)))
        skip = {Role.CAMERA_INFO} if info_topic is not None else set()
        skip |= {Role.IMAGE} if image_topic is not None else set()
        for item in reader.messages([r for r in roles if r not in skip]):
            rec = item.record
            if isinstance(rec, Scan):
                scans.append(rec)
            elif isinstance(rec, Pose2D):
                (ref if item.role is Role.REFERENCE else odom).append(rec)
            elif isinstance(rec, CameraInfo):
                info = info or rec
            elif isinstance(rec, Detections):
                detections.append(rec)
            elif isinstance(rec, Image) and detector is not None:
                boxes.append(Detections(rec.stamp_ns, rec.log_time_ns, rec.frame_id, detector(rec)))
        # an unset stamp (recording.unset_stamps): its log time, the nearest we know, on the scans' clock
        clock = scans_clock(scans, config.io.clock_mismatch_s)
        is_unset = unset_stamps([d.stamp_ns for d in detections])
        unset = int(is_unset.sum())
        offset_ns = round(config.doorpose.detection_time_offset_s * 1e9)  # a detector's known latency, taken out
        boxes += [replace(d, stamp_ns=(clock.stamp_at(d.log_time_ns) if u else d.stamp_ns) + offset_ns)
                  for d, u in zip(detections, is_unset, strict=True)]
        frames, base_note = resolve_base_frame(tf, config.frames)
        odom, notes = odometry_poses(odom, tf, reader.roles.topic(Role.ODOMETRY) is not None, frames)
        odometry, reference = robot_pose_series(odom, ref, tf, frames)
        notes = [*([base_note] if base_note else []), *notes]
        warnings = [*reader.warnings, *warnings_pre, *notes]
        if unset:
            warnings.append(f"{unset} of {len(boxes)} detection messages have header stamp 0 (unset): timed by "
                            f"their log time")
        if detector is None and reader.roles.topic(Role.IMAGE) is not None and config.doorpose.max_detection_latency_s:
            boxes, note = _on_image_stamps(boxes, reader, config)
            warnings += [note] if note else []
    if info is None:
        raise LogContentError("camera_info topic has no messages", path=path, topic=info_name)
    if not scans:
        raise LogContentError("scan topic has no messages", path=path)
    unknown = sorted({b.frame_id for b in boxes} - {info.frame_id} - tf.frames)
    if unknown:  # with one camera the boxes are its; with several a wrong one may have been taken
        warnings.append(f"the boxes name frame(s) {unknown}, which neither the CameraInfo ({info.frame_id!r}) nor TF "
                        f"knows: taken as {info.frame_id!r}'s (set topics.camera_info if the log has another camera)")
    return DoorPoseInputs(str(path), tf, info, sorted(scans, key=lambda s: s.stamp_ns),
                          sorted(boxes, key=lambda d: d.stamp_ns), reference, odometry, warnings, frames.base_link,
                          clock)


def _first_message(reader: LogReader, topic: str) -> RawMessage | None:
    """The first message of ``topic`` (None when it has none); the rest of the topic is not read."""
    return next(iter(reader.raw_messages([topic])), None)


# image_transport's sub-topics of an image topic (``.../image_raw/compressed``).
_TRANSPORTS = frozenset({"compressed", "compressedDepth", "theora", "zstd", "ffmpeg"})


def _camera_info_of_boxes(reader: LogReader, box_topic: str | None, config: DoorbatchConfig
                          ) -> tuple[str | None, str | None]:
    """The CameraInfo topic of the camera the boxes (or images) come from, in a log with several cameras
    (a RealSense publishes colour, depth and infrared CameraInfo): the one whose ``frame_id`` is the boxes'
    frame, else the one beside the boxes' topic (image_transport: ``.../camera_info`` next to ``.../image*``).
    None (with no note) when the log has one CameraInfo topic or the config names it; then the role's topic is
    used. The note says when the choice was a guess."""
    infos = sorted(t.name for t in reader.topics.values() if t.msgtype == CAMERA_INFO)
    if len(infos) < 2 or config.topics.camera_info is not None or box_topic is None:
        return None, None
    def frame_of(topic: str) -> str:
        raw = _first_message(reader, topic)
        return str(raw.msg.header.frame_id).lstrip("/") if raw is not None else ""

    box_frame = frame_of(box_topic)
    frames = {name: frame_of(name) for name in infos}
    same_frame = [name for name in infos if box_frame and frames[name] == box_frame]
    if len(same_frame) == 1:
        return same_frame[0], None
    base = box_topic.rsplit("/", 1)[0] if box_topic.rsplit("/", 1)[-1] in _TRANSPORTS else box_topic
    namespace = base.rsplit("/", 1)[0]
    beside = [name for name in (same_frame or infos) if name.rsplit("/", 1)[0] == namespace]
    if len(beside) == 1:
        return beside[0], None
    chosen = reader.roles.topic(Role.CAMERA_INFO)
    return chosen, (f"{len(infos)} CameraInfo topics and none matches the frame {box_frame!r} of {box_topic}: "
                    f"using {chosen} (set topics.camera_info)")


# Encodings a detector cannot see a door in: depth and other non-visual images (sensor_msgs/image_encodings).
_NOT_VISUAL = ("16UC1", "32FC1", "16SC1", "32SC1", "64FC1", "mono16")


def _colour_image_topic(reader: LogReader, config: DoorbatchConfig) -> str | None:
    """For ``--detector`` in a log with several image topics (a RealSense's colour, depth and infrared): a colour
    one (an rgb/bgr/Bayer/YUV encoding, or a compressed image that is not ``compressedDepth``), else a visual
    one. None when the log has one image topic or the config names it (the role's topic is used)."""
    names = sorted(t.name for t in reader.topics.values() if t.msgtype in (IMAGE, COMPRESSED_IMAGE))
    if len(names) < 2 or config.topics.image is not None:
        return None

    def rank(name: str) -> int:
        raw = _first_message(reader, name)
        if raw is None:
            return 3
        if raw.msgtype == COMPRESSED_IMAGE:
            return 2 if "depth" in str(raw.msg.format).lower() else 0
        encoding = str(raw.msg.encoding)
        return 2 if encoding in _NOT_VISUAL else 1 if encoding in ("mono8", "8UC1") else 0

    ranks = {name: rank(name) for name in names}
    best = min(names, key=lambda n: (ranks[n], n != reader.roles.topic(Role.IMAGE)))
    return best if ranks[best] < 2 else None


def _on_image_stamps(boxes: list[Detections], reader: LogReader, config: DoorbatchConfig
                     ) -> tuple[list[Detections], str | None]:
    """Detections stamped when they were published rather than with their image's stamp (a node stamping with
    ``now()``): where the log has images of the boxes' frame (any image topic; the images of the log's one
    camera frame where the boxes name another, e.g. camera_link for camera_optical) and hardly any box message
    carries an image's stamp (under a tenth: a log with dropped images keeps its stamps), each takes the stamp
    of the latest image of its frame before it (within ``doorpose.max_detection_latency_s``; up to
    ``doorpose.max_detection_lead_s`` after it, for clocks that jitter), with a note."""
    names = [t.name for t in reader.topics.values() if t.msgtype in (IMAGE, COMPRESSED_IMAGE)]
    stamps: dict[str, set[int]] = {}
    for raw in reader.raw_messages(names):
        header = raw.msg.header
        stamps.setdefault(str(header.frame_id).lstrip("/"), set()).add(stamp_to_ns(header.stamp))
    own = sum(b.stamp_ns in stamps.get(b.frame_id, ()) for b in boxes)
    if not stamps or not boxes or 10 * own >= len(boxes):
        return boxes, None
    latency = int(config.doorpose.max_detection_latency_s * 1e9)
    lead = int(config.doorpose.max_detection_lead_s * 1e9)
    ordered = {frame: np.array(sorted(v), dtype=np.int64) for frame, v in stamps.items()}
    only = next(iter(ordered.values())) if len(ordered) == 1 else None  # one camera: its images, whatever frame
    out, moved = [], 0
    for b in boxes:
        images = ordered.get(b.frame_id, only)
        k = -1 if images is None else int(np.searchsorted(images, b.stamp_ns + lead, side="right")) - 1
        if images is not None and k >= 0 and images[k] != b.stamp_ns and b.stamp_ns - int(images[k]) <= latency:
            out.append(replace(b, stamp_ns=int(images[k])))
            moved += 1
        else:
            out.append(b)
    note = (f"{moved} of {len(boxes)} detection messages carry no image's stamp: given the stamp of the latest image "
            f"before them (detections stamped on publishing?); a detector slower than a camera period pairs its boxes "
            f"with a later image that way, so give its latency: --set doorpose.detection_time_offset_s=-LATENCY"
            ) if moved else None
    return out, note
