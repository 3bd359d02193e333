"""vision_msgs/Detection2DArray as the ROS 2 distributions before Humble lay it out: read, and written back."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from doorbatch.io.decode import decode_detections
from doorbatch.io.log_writer import to_ros2
from doorbatch.io.reader import RawMessage
from doorbatch.io.typestore import new_ros2_typestore
from doorbatch.records import Detection

# vision_msgs 2.x (Foxy: string id beside the score) and 3.x (Galactic: ObjectHypothesis, geometry_msgs/Pose2D
# centre), from their .msg files.
_LAYOUTS = {
    "foxy": {
        "vision_msgs/msg/BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
        "vision_msgs/msg/ObjectHypothesisWithPose": "string id\nfloat64 score\n"
                                                    "geometry_msgs/PoseWithCovariance pose\n",
        "vision_msgs/msg/Detection2D": "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
                                       "vision_msgs/BoundingBox2D bbox\nsensor_msgs/Image source_img\n"
                                       "bool is_tracking\nstring tracking_id\n",
        "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
    },
    "galactic": {
        "vision_msgs/msg/BoundingBox2D": "geometry_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n",
        "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
        "vision_msgs/msg/ObjectHypothesisWithPose": "vision_msgs/ObjectHypothesis hypothesis\n"
                                                    "geometry_msgs/PoseWithCovariance pose\n",
        "vision_msgs/msg/Detection2D": "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
                                       "vision_msgs/BoundingBox2D bbox\nstring id\n",
        "vision_msgs/msg/Detection2DArray": "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n",
    },
}
BOXES = [("door", 0.9, 320.0, 240.0, 200.0, 400.0), ("handle", 0.6, 390.0, 250.0, 20.0, 20.0)]


def _store(layout: str) -> Typestore:
    store = get_typestore(Stores.ROS2_HUMBLE)
    for name, text in _LAYOUTS[layout].items():
        store.register(get_types_from_msg(text, name))
    return store


def _array(store: Typestore, layout: str) -> Any:
    t = store.types
    header = t["std_msgs/msg/Header"](stamp=t["builtin_interfaces/msg/Time"](sec=5, nanosec=0), frame_id="cam")
    pose = t["geometry_msgs/msg/PoseWithCovariance"](
        pose=t["geometry_msgs/msg/Pose"](position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                         orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
        covariance=np.zeros(36))
    dets = []
    for cls, score, cx, cy, w, h in BOXES:
        hyp = (t["vision_msgs/msg/ObjectHypothesisWithPose"](id=cls, score=score, pose=pose) if layout == "foxy" else
               t["vision_msgs/msg/ObjectHypothesisWithPose"](
                   hypothesis=t["vision_msgs/msg/ObjectHypothesis"](class_id=cls, score=score), pose=pose))
        bbox = t["vision_msgs/msg/BoundingBox2D"](center=t["geometry_msgs/msg/Pose2D"](x=cx, y=cy, theta=0.0),
                                                  size_x=w, size_y=h)
        extra: dict[str, Any] = {"id": ""} if layout == "galactic" else {
            "source_img": t["sensor_msgs/msg/Image"](header=header, height=0, width=0, encoding="", is_bigendian=0,
                                                     step=0, data=np.zeros(0, np.uint8)),
            "is_tracking": False, "tracking_id": ""}
        dets.append(t["vision_msgs/msg/Detection2D"](header=header, results=[hyp], bbox=bbox, **extra))
    return t["vision_msgs/msg/Detection2DArray"](header=header, detections=dets)


@pytest.mark.parametrize("layout", ["foxy", "galactic"])
def test_older_layouts_read_and_write_back_as_humble(layout: str) -> None:
    store = _store(layout)
    msg = store.deserialize_cdr(store.serialize_cdr(_array(store, layout), "vision_msgs/msg/Detection2DArray"),
                                "vision_msgs/msg/Detection2DArray")
    want = tuple(Detection(*box) for box in BOXES)
    assert decode_detections(msg, 0).detections == want
    raw = RawMessage("/detections", "vision_msgs/msg/Detection2DArray", 5_000_000_000, msg, False, store)
    out, out_store = to_ros2(raw, {}, target := new_ros2_typestore())
    assert out_store is target  # what the annotated MCAP's schema (Humble's) describes
    data = out_store.serialize_cdr(out, "vision_msgs/msg/Detection2DArray")
    back = target.deserialize_cdr(data, "vision_msgs/msg/Detection2DArray")
    assert decode_detections(back, 0).detections == want


def test_one_output_of_two_logs_with_two_layouts_keeps_every_message_decodable(tmp_path: Path) -> None:
    """doorbatch map --mcap writes the passes of several logs into one MCAP: a Humble log and a Foxy-era one
    must both read back. The arrays become Humble's layout; a single Detection2D, whose Foxy wire layout differs
    (source_img, is_tracking, tracking_id), keeps its own schema beside Humble's."""
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.reader import open_log
    from doorbatch.io.ros_messages import detection_array

    humble, foxy = new_ros2_typestore(), _store("foxy")
    logs = [(humble, "humble"), (foxy, "foxy"), (humble, "humble")]  # no answer may carry over between logs
    out = tmp_path / "out.mcap"
    array_type, one_type = "vision_msgs/msg/Detection2DArray", "vision_msgs/msg/Detection2D"
    with LogWriter(out) as writer:
        for k, (store, layout) in enumerate(logs):
            msg = _array(store, layout) if layout == "foxy" else detection_array(5_000_000_000, "cam", BOXES)
            msg = store.deserialize_cdr(store.serialize_cdr(msg, array_type), array_type)
            writer.write_raw(RawMessage("/detections", array_type, k + 1, msg, False, store))
            writer.write_raw(RawMessage("/one", one_type, k + 1, msg.detections[0], False, store))
    with open_log(out) as reader:
        raws = list(reader.raw_messages())
    assert [r.topic for r in raws] == ["/detections", "/one"] * 3
    for raw in raws:
        if raw.topic == "/detections":
            assert decode_detections(raw.msg, 0).detections == tuple(Detection(*b) for b in BOXES)
        else:
            assert raw.msg.bbox.size_x == 200.0 and len(raw.msg.results) == 1
