"""YOLO decoding: letterbox geometry, both output layouts (v5 with objectness, v8 without) give the same
boxes after threshold and NMS; an unknown model format is a usage error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from yolo_cases import IMAGE, ROWS, SIZE, check_detections, detector_config

from doorbatch.errors import UsageError
from doorbatch.io.detector_model import load_detector
from doorbatch.pipeline.doorpose.yolo import decode_detections, letterbox, yolo_candidates


def test_letterbox_scale_and_padding() -> None:
    box = letterbox(IMAGE, SIZE)
    assert box.blob.shape == (1, 3, SIZE, SIZE) and box.blob.dtype == np.float32
    assert (box.scale, box.pad_x, box.pad_y) == (0.5, 0.0, 8.0)
    assert box.blob[0, :, 0, 0] == pytest.approx([114 / 255] * 3)  # grey padding
    assert box.blob[0, :, 8:56, :].max() == 0.0  # the black image


def test_decoder_reads_both_layouts_alike() -> None:
    box = letterbox(IMAGE, SIZE)
    cfg = detector_config()
    check_detections(decode_detections(ROWS[None], box, (96, 128), cfg.class_names, 0.25, 0.45, "v5"))
    v8 = np.concatenate([ROWS[:, :4], ROWS[:, 4:5] * ROWS[:, 5:]], axis=1).T[None]  # [1, 4 + C, N]
    check_detections(decode_detections(v8, box, (96, 128), cfg.class_names, 0.25, 0.45, "auto"))
    assert yolo_candidates(ROWS[None])[0].shape == (20, 4)


def test_unknown_model_format_is_a_usage_error(tmp_path: Path) -> None:
    bad = tmp_path / "model.tflite"
    bad.write_bytes(b"x")
    with pytest.raises(UsageError, match="unknown model format"):
        load_detector(bad)
