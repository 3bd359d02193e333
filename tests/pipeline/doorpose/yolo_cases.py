"""Known YOLO outputs for the detector tests: an image, a v5 table of boxes in input pixels, and the
detections they must decode to."""

from __future__ import annotations

from typing import Any

import numpy as np

from doorbatch.config import DoorPoseConfig

SIZE = 64  # network input; the image is 128 × 96: scale 0.5, 8 px of padding above and below
IMAGE = np.zeros((96, 128, 3), dtype=np.uint8)
# v5 rows in input pixels: cx, cy, w, h, objectness, p(door), p(handle)
ROWS = np.array([
    [32.0, 30.0, 20.0, 30.0, 0.9, 0.95, 0.05],  # door: image box centre (64, 44), size 40 × 60
    [33.0, 30.0, 20.0, 30.0, 0.8, 0.90, 0.10],  # the same door again, weaker: NMS removes it
    [38.0, 32.0, 4.0, 2.0, 0.8, 0.10, 0.90],  # handle inside the door: centre (76, 48), size 8 × 4
    [10.0, 50.0, 6.0, 6.0, 0.2, 0.90, 0.10],  # below the threshold (0.18)
    *[[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]] * 16,  # empty anchors
], dtype=np.float32)
EXPECTED = [("door", 0.855, 64.0, 44.0, 40.0, 60.0), ("handle", 0.72, 76.0, 48.0, 8.0, 4.0)]


def detector_config() -> DoorPoseConfig:
    return DoorPoseConfig(input_size_px=SIZE, confidence_threshold=0.25, nms_iou_threshold=0.45)


def check_detections(dets: tuple[Any, ...]) -> None:
    got = [(d.class_id, d.score, d.center_x, d.center_y, d.size_x, d.size_y) for d in dets]
    assert [g[0] for g in got] == [e[0] for e in EXPECTED]
    for g, e in zip(got, EXPECTED, strict=True):
        np.testing.assert_allclose(g[1:], e[1:], atol=1e-4)
