"""Door pose speed: fusion + line fit per frame, and detector inference per image on the CPU.

Fusion: F frames of simulated door scenes (paper 003's sensors: 360-beam laser, 640×480 camera; 1-2
obstacles near the door edges, noisy boxes); per frame the timed work is the scan into the camera frame
through TF, the box's ray bearings, the door points, the fit (RANSAC: 1000 trials, 0.01 m) and the pose
(``scan_in_camera`` + ``estimate_door``). Best of the repeats, per frame.

Detector: a YOLOv5s-shaped network (the paper's model size: width 0.5, depth 0.33, 3 scales × 3 anchors,
640×640 input, output [1, 25200, 5 + C]) with random weights and YOLOv5's prior biases (about 8 objects per
image), exported to ONNX and TorchScript into a temp folder, timed on a 640×480 image twice: the model's
forward alone (blob in, output back) and through ``detect_image`` (letterbox, inference, decoding, NMS).
Random weights do not change the inference's arithmetic, so that time is a trained model's of this shape;
the prior biases keep NMS to the few candidates a trained model leaves (without them, random objectness
let ~11,600 of the 25,200 rows through and NMS, not the network, took a third of the time). Needs the
``torch`` extra (skipped without it).

Run: ``taskset -c 0 python bench/bench_doorpose.py [--frames F] [--repeats R] [--images N]
[--torch-device D]`` (one core; the script also sets OpenCV's and torch's thread counts to 1; D runs the
TorchScript model on a GPU, ``cuda``).
"""

from __future__ import annotations

import argparse
import math
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from doorbatch.config import DoorPoseConfig
from doorbatch.geometry.camera import scan_in_camera
from doorbatch.pipeline.doorpose.fusion import estimate_door
from doorbatch.pipeline.doorpose.line_fit import LineFit
from doorbatch.records import Detection, Scan
from doorbatch.sim.door_scene import CAMERA_FRAME, LASER_FRAME, DoorScene, make_door_scene, observe
from doorbatch.sim.sensors import simulate_scan


def frames(n: int, rng: np.random.Generator) -> list[tuple[DoorScene, Scan, tuple[Detection, ...]]]:
    """Simulated frames with a usable door box."""
    out = []
    while len(out) < n:
        scene = make_door_scene(rng)
        pose = np.array([rng.uniform(-0.6, 0.6), -rng.uniform(1.5, 3.0), math.pi / 2 + rng.uniform(-0.25, 0.25)])
        obs = observe(scene, pose, rng)
        lm = scene.laser
        ranges = simulate_scan(pose, scene.scene, lm, rng).ranges.astype(np.float32)
        scan = Scan(0, 0, LASER_FRAME, lm.angle_min_rad, lm.angle_increment_rad, lm.range_min_m, lm.range_max_m,
                    ranges)
        if any(d.class_id == "door" for d in obs.detections):
            out.append((scene, scan, obs.detections))
    return out


def bench_fusion(n_frames: int, repeats: int) -> dict[str, float]:
    """ms per frame of scan → camera frame → door pose, per fit (best of the repeats)."""
    data = frames(n_frames, np.random.default_rng(0))
    cfg = DoorPoseConfig()
    result = {}
    for fit in LineFit:
        best = math.inf
        for _ in range(repeats):
            rng = np.random.default_rng(1)
            t0 = time.perf_counter()
            for scene, scan, dets in data:
                points, _ = scan_in_camera(scan, scene.tf, CAMERA_FRAME)
                estimate_door(scene.camera, dets, points, cfg, rng, fit)
            best = min(best, (time.perf_counter() - t0) / len(data))
        result[fit.value] = 1e3 * best
    return result


def yolov5s_like(num_classes: int = 2) -> Any:
    """A YOLOv5s (v6.0) architecture: Conv-BN-SiLU, C3, SPPF, PAN neck, Detect head with grid decoding."""
    import torch
    from torch import nn

    class Conv(nn.Module):
        def __init__(self, c1: int, c2: int, k: int = 1, s: int = 1, p: int | None = None) -> None:
            super().__init__()
            self.conv = nn.Conv2d(c1, c2, k, s, k // 2 if p is None else p, bias=False)
            self.bn = nn.BatchNorm2d(c2)
            self.act = nn.SiLU()

        def forward(self, x: Any) -> Any:
            return self.act(self.bn(self.conv(x)))

    class Bottleneck(nn.Module):
        def __init__(self, c: int, shortcut: bool) -> None:
            super().__init__()
            self.cv1, self.cv2, self.add = Conv(c, c, 1), Conv(c, c, 3), shortcut

        def forward(self, x: Any) -> Any:
            y = self.cv2(self.cv1(x))
            return x + y if self.add else y

    class C3(nn.Module):
        def __init__(self, c1: int, c2: int, n: int = 1, shortcut: bool = True) -> None:
            super().__init__()
            c = c2 // 2
            self.cv1, self.cv2, self.cv3 = Conv(c1, c, 1), Conv(c1, c, 1), Conv(2 * c, c2, 1)
            self.m = nn.Sequential(*(Bottleneck(c, shortcut) for _ in range(n)))

        def forward(self, x: Any) -> Any:
            return self.cv3(torch.cat([self.m(self.cv1(x)), self.cv2(x)], 1))

    class SPPF(nn.Module):
        def __init__(self, c1: int, c2: int) -> None:
            super().__init__()
            self.cv1, self.cv2 = Conv(c1, c1 // 2, 1), Conv(c1 * 2, c2, 1)
            self.m = nn.MaxPool2d(5, 1, 2)

        def forward(self, x: Any) -> Any:
            x = self.cv1(x)
            y1 = self.m(x)
            y2 = self.m(y1)
            return self.cv2(torch.cat([x, y1, y2, self.m(y2)], 1))

    anchors = torch.tensor([[10, 13, 16, 30, 33, 23], [30, 61, 62, 45, 59, 119], [116, 90, 156, 198, 373, 326]],
                           dtype=torch.float32).view(3, 1, 3, 1, 1, 2)
    strides = (8, 16, 32)
    no = 5 + num_classes

    class Net(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.b0, self.b1, self.b2 = Conv(3, 32, 6, 2, 2), Conv(32, 64, 3, 2), C3(64, 64, 1)
            self.b3, self.b4 = Conv(64, 128, 3, 2), C3(128, 128, 2)
            self.b5, self.b6 = Conv(128, 256, 3, 2), C3(256, 256, 3)
            self.b7, self.b8, self.b9 = Conv(256, 512, 3, 2), C3(512, 512, 1), SPPF(512, 512)
            self.h10, self.h13 = Conv(512, 256, 1), C3(512, 256, 1, False)
            self.h14, self.h17 = Conv(256, 128, 1), C3(256, 128, 1, False)
            self.h18, self.h20 = Conv(128, 128, 3, 2), C3(256, 256, 1, False)
            self.h21, self.h23 = Conv(256, 256, 3, 2), C3(512, 512, 1, False)
            self.up = nn.Upsample(scale_factor=2.0, mode="nearest")
            self.det = nn.ModuleList(nn.Conv2d(c, 3 * no, 1) for c in (128, 256, 512))
            self.register_buffer("anchors", anchors)
            with torch.no_grad():  # YOLOv5's prior biases (Detect._initialize_biases): ~8 objects per image, so
                for conv, s in zip(self.det, strides, strict=True):  # NMS sees a trained model's few candidates
                    b = conv.bias.view(3, no)
                    b[:, 4] += math.log(8 / (640 / s) ** 2)
                    b[:, 5:] += math.log(0.6 / (num_classes - 0.99))

        def forward(self, x: Any) -> Any:
            p3 = self.b4(self.b3(self.b2(self.b1(self.b0(x)))))
            p4 = self.b6(self.b5(p3))
            p5 = self.b9(self.b8(self.b7(p4)))
            h10 = self.h10(p5)
            h14 = self.h14(self.h13(torch.cat([self.up(h10), p4], 1)))
            o3 = self.h17(torch.cat([self.up(h14), p3], 1))
            o4 = self.h20(torch.cat([self.h18(o3), h14], 1))
            o5 = self.h23(torch.cat([self.h21(o4), h10], 1))
            outs = []
            for i, o in enumerate((o3, o4, o5)):
                y = self.det[i](o)
                _, _, h, w = y.shape
                y = y.view(1, 3, no, h, w).permute(0, 1, 3, 4, 2).sigmoid()
                gy, gx = torch.meshgrid(torch.arange(h, device=y.device), torch.arange(w, device=y.device),
                                        indexing="ij")
                grid = torch.stack([gx, gy], -1).view(1, 1, h, w, 2).float()
                xy = (y[..., :2] * 2 - 0.5 + grid) * strides[i]
                wh = (y[..., 2:4] * 2) ** 2 * self.anchors[i]
                outs.append(torch.cat([xy, wh, y[..., 4:]], -1).view(1, -1, no))
            return torch.cat(outs, 1)

    return Net().eval()


def bench_detectors(n_images: int, torch_device: str = "cpu") -> dict[str, float]:
    """ms per 640×480 image through detect_image, for the ONNX (OpenCV DNN) and TorchScript paths.

    The TorchScript model is traced and run on ``torch_device`` (a GPU's time includes the copies of the
    blob in and the output back, as ``doorbatch doorpose`` pays them).
    """
    try:
        import torch
    except ImportError:
        return {}
    from doorbatch.io.detector_model import load_detector
    from doorbatch.pipeline.doorpose.yolo import detect_image, letterbox

    torch.manual_seed(0)
    torch.set_num_threads(1)
    net = yolov5s_like()
    x = torch.zeros(1, 3, 640, 640)
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    cfg = DoorPoseConfig()
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        onnx_path, ts_path = Path(tmp) / "yolov5s_like.onnx", Path(tmp) / "yolov5s_like.pt"
        with torch.no_grad():
            torch.onnx.export(net, (x,), str(onnx_path), dynamo=False, opset_version=17, input_names=["images"],
                              output_names=["output0"])
            torch.jit.trace(net.to(torch_device), x.to(torch_device)).save(str(ts_path))
        for name, path in (("onnx_opencv_dnn", onnx_path), (f"torchscript_{torch_device}", ts_path)):
            model = load_detector(path, torch_device)
            for _ in range(3):  # warm up: TorchScript's profiling executor optimizes over the first calls
                detect_image(model.forward, image, cfg)
            blob = letterbox(image, cfg.input_size_px).blob
            t0 = time.perf_counter()
            for _ in range(n_images):
                model.forward(blob)
            out[f"{name} forward"] = 1e3 * (time.perf_counter() - t0) / n_images
            t0 = time.perf_counter()
            for _ in range(n_images):
                detect_image(model.forward, image, cfg)
            out[f"{name} detect_image"] = 1e3 * (time.perf_counter() - t0) / n_images
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--images", type=int, default=10)
    ap.add_argument("--torch-device", default="cpu", help="device of the TorchScript detector (cpu, cuda)")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    print(f"machine: {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"opencv {cv2.__version__}")
    for fit, ms in bench_fusion(args.frames, args.repeats).items():
        print(f"fusion + {fit:6s}: {ms:7.3f} ms per frame ({args.frames} frames, best of {args.repeats})")
    for name, ms in bench_detectors(args.images, args.torch_device).items():
        print(f"detector {name:29s}: {ms:7.1f} ms per 640x480 image (YOLOv5s shape, {args.images} images)")


if __name__ == "__main__":
    main()
