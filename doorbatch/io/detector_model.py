"""Loading a user's object detector from a file: ONNX through OpenCV DNN, TorchScript through the ``torch``
extra. Nothing is downloaded: the model is the file the user names.

A loaded model maps a letterboxed blob (1, 3, S, S) float32 to its raw output array (see
:mod:`doorbatch.pipeline.doorpose.yolo` for the layouts).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import numpy.typing as npt

from doorbatch.errors import LogReadError, OptionalDependencyError, UsageError

log = logging.getLogger(__name__)

ONNX_SUFFIXES = (".onnx",)
TORCHSCRIPT_SUFFIXES = (".pt", ".torchscript", ".ptl")


@dataclass(frozen=True)
class DetectorModel:
    """A loaded detector: ``forward(blob) -> raw output``, its kind and path."""

    kind: str  # "onnx" or "torchscript"
    path: str
    forward: Callable[[npt.NDArray[np.float32]], npt.NDArray[np.float32]]


def _onnx(path: Path) -> DetectorModel:
    try:
        net = cv2.dnn.readNetFromONNX(str(path))
    except cv2.error as err:
        raise LogReadError(f"OpenCV DNN cannot read the ONNX model: {str(err).strip().splitlines()[-1]}",
                           path=path) from err

    def forward(blob: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        net.setInput(blob)
        return np.asarray(net.forward(), dtype=np.float32)

    return DetectorModel("onnx", str(path), forward)


def _torchscript(path: Path, device: str) -> DetectorModel:
    try:
        import torch
    except ImportError as err:
        raise OptionalDependencyError("torch (for TorchScript detectors)", "torch") from err
    try:
        model: Any = torch.jit.load(str(path), map_location=device)  # type: ignore[no-untyped-call]
    except (RuntimeError, ValueError) as err:
        raise LogReadError(f"torch.jit.load cannot read the model: {str(err).strip().splitlines()[0]}",
                           path=path) from err
    model.eval()

    def forward(blob: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
        with torch.no_grad():
            out = model(torch.from_numpy(blob).to(device))
        if isinstance(out, list | tuple):  # YOLOv5 exports return (predictions, feature maps)
            out = out[0]
        return np.asarray(out.detach().cpu().numpy(), dtype=np.float32)

    return DetectorModel("torchscript", str(path), forward)


def load_detector(path: Path, torch_device: str = "cpu") -> DetectorModel:
    """The detector in ``path`` chosen by suffix: .onnx (OpenCV DNN) or .pt/.torchscript (TorchScript).

    Raises:
        UsageError: the file does not exist or has another suffix.
        LogReadError: the file is not a readable model.
        OptionalDependencyError: a TorchScript model without torch installed.
    """
    if not path.is_file():
        raise UsageError(f"detector model {path} does not exist")
    suffix = path.suffix.lower()
    if suffix in ONNX_SUFFIXES:
        return _onnx(path)
    if suffix in TORCHSCRIPT_SUFFIXES:
        return _torchscript(path, torch_device)
    raise UsageError(f"detector {path}: unknown model format {suffix!r} (use .onnx, or .pt / .torchscript "
                     "for TorchScript)")
