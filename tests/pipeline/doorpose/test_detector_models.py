"""Detector paths are real: a tiny model with the YOLOv5 output layout, weights set to known boxes, exported
with torch.onnx.export and torch.jit, run through OpenCV DNN and TorchScript; after letterbox, threshold and
NMS the known boxes come back in image pixels. Skipped without the ``torch`` extra."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from door_logs import door_log
from yolo_cases import IMAGE, ROWS, SIZE, check_detections, detector_config

from doorbatch.cli import main
from doorbatch.io.detector_model import load_detector
from doorbatch.io.parquet import read_table
from doorbatch.pipeline.doorpose.yolo import detect_image
from doorbatch.sim.door_scene import DoorSceneSpec, make_door_scene, observe

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


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no CUDA"))])
def test_torchscript_model(tmp_path: Path, device: str) -> None:
    """Traced on the CPU, loaded onto ``device`` (``doorpose.torch_device``): the same boxes."""
    path = tmp_path / "tiny_v5.pt"
    torch.jit.trace(_FixedHead(ROWS).eval(), torch.zeros(1, 3, SIZE, SIZE)).save(str(path))
    model = load_detector(path, device)
    assert model.kind == "torchscript"
    check_detections(detect_image(model.forward, IMAGE, detector_config()))


def test_doorpose_cli_runs_an_onnx_detector_over_the_logs_images(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(0, 0)))
    pose = np.array([0.1, -2.2, math.pi / 2 + 0.05])
    log = door_log(tmp_path / "door.mcap", scene, np.repeat(pose[None], 3, axis=0), rng, images=True)
    # a model that outputs this view's true door box; 640×480 images letterboxed to 640: 80 px above
    door = next(b for b in observe(scene, pose, np.random.default_rng(0)).true_boxes if b.class_id == "door")
    rows = np.zeros((12, 7), dtype=np.float32)
    rows[0] = [door.center_x, door.center_y + 80.0, door.size_x, door.size_y, 0.9, 0.95, 0.05]
    model = tmp_path / "door.onnx"
    torch.onnx.export(_FixedHead(rows).eval(), (torch.zeros(1, 3, 640, 640),), str(model), dynamo=False,
                      input_names=["images"], output_names=["output0"])
    out = tmp_path / "run"
    assert main(["doorpose", str(log), "-o", str(out), "--detector", str(model), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["door_poses"] == 3
    t = read_table("door_poses", out / "door_poses.parquet").to_pydict()
    np.testing.assert_allclose(t["center_x"], 0.0, atol=0.03)
    np.testing.assert_allclose(t["center_y"], 0.0, atol=0.03)
    np.testing.assert_allclose(t["width"], scene.door_width_m, atol=0.03)
    np.testing.assert_allclose(t["yaw"], -math.pi / 2, atol=0.03)
    manifest = json.loads((out / "manifest.json").read_text())
    assert any(i["path"].endswith("door.onnx") for i in manifest["inputs"])
