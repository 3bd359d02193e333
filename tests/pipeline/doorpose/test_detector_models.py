"""Detector paths are real: a tiny model with the YOLOv5 output layout, weights set to known boxes, exported
with torch.onnx.export and torch.jit, run through OpenCV DNN and TorchScript; after letterbox, threshold and
NMS the known boxes come back in image pixels. Skipped without the ``torch`` extra."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from yolo_cases import IMAGE, ROWS, SIZE, check_detections, detector_config

from doorbatch.io.detector_model import load_detector
from doorbatch.pipeline.doorpose.yolo import detect_image

torch = pytest.importorskip("torch")
pytest.importorskip("onnx")



class _FixedHead(torch.nn.Module):  # type: ignore[misc]
    """Outputs its weight table (the known boxes) for any input, in the YOLOv5 layout [1, N, 5 + C]."""

    def __init__(self, table: np.ndarray) -> None:
        super().__init__()
        self.table = torch.nn.Parameter(torch.from_numpy(table))

    def forward(self, x: Any) -> Any:
        return self.table.unsqueeze(0) * (1.0 + 0.0 * x.mean())


def test_onnx_model_through_opencv_dnn(tmp_path: Path) -> None:
    path = tmp_path / "tiny_v5.onnx"
    torch.onnx.export(_FixedHead(ROWS).eval(), (torch.zeros(1, 3, SIZE, SIZE),), str(path), dynamo=False,
                      input_names=["images"], output_names=["output0"])
    model = load_detector(path)
    assert model.kind == "onnx"
    check_detections(detect_image(model.forward, IMAGE, detector_config()))


def test_torchscript_model(tmp_path: Path) -> None:
    path = tmp_path / "tiny_v5.pt"
    torch.jit.trace(_FixedHead(ROWS).eval(), torch.zeros(1, 3, SIZE, SIZE)).save(str(path))
    model = load_detector(path)
    assert model.kind == "torchscript"
    check_detections(detect_image(model.forward, IMAGE, detector_config()))
