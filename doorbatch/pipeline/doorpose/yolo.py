"""YOLOv5 / YOLOv8 pre- and post-processing around a user's exported detector (paper 003, Sec. III-A).

* Letterbox (YOLOv5's ``letterbox``): scale r = min(S/H, S/W), resize to (round(W·r), round(H·r)) bilinearly,
  pad to S×S with grey 114 split evenly; the blob is RGB / 255, NCHW float32.
* Output layouts: v5 ``[1, N, 5 + C]`` rows (cx, cy, w, h, objectness, class scores), score = objectness ×
  class score; v8 ``[1, 4 + C, N]`` columns (cx, cy, w, h, class scores), score = class score. ``auto`` takes
  the layout whose box count is the larger dimension (anchors outnumber channels in every real export).
* Boxes above the confidence threshold, mapped back through the letterbox (u = (u' − pad_x)/r), clipped to
  the image, then non-maximum suppression per class (``cv2.dnn.NMSBoxesBatched``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorPoseConfig
from doorbatch.records import Detection

FloatArray = npt.NDArray[np.float64]
Layout = Literal["auto", "v5", "v8"]
LETTERBOX_GREY = 114


@dataclass(frozen=True)
class Letterbox:
    """The letterbox of one image: input blob (1, 3, S, S), scale r and padding (pixels of the input)."""

    blob: npt.NDArray[np.float32]
    scale: float
    pad_x: float
    pad_y: float


def letterbox(pixels: npt.NDArray[np.uint8], size_px: int) -> Letterbox:
    """Letterboxed network input of an RGB (H, W, 3) or grey (H, W) image (module docstring)."""
    rgb = np.repeat(pixels[:, :, None], 3, axis=2) if pixels.ndim == 2 else pixels[:, :, :3]
    h, w = rgb.shape[:2]
    r = min(size_px / h, size_px / w)
    new_w, new_h = round(w * r), round(h * r)
    resized = rgb if (new_w, new_h) == (w, h) else cv2.resize(rgb, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    pad_x, pad_y = (size_px - new_w) / 2, (size_px - new_h) / 2
    left, top = round(pad_x - 0.1), round(pad_y - 0.1)
    canvas = np.full((size_px, size_px, 3), LETTERBOX_GREY, dtype=np.uint8)
    canvas[top:top + new_h, left:left + new_w] = resized
    blob = (canvas.transpose(2, 0, 1)[None].astype(np.float32) / 255.0).copy()
    return Letterbox(blob, r, float(left), float(top))


def yolo_candidates(output: npt.ArrayLike, layout: Layout = "auto"
                    ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """Boxes (N, 4) cx, cy, w, h in input pixels, best-class scores (N,) and class indices (N,) of a raw
    YOLO output (module docstring)."""
    out = np.asarray(output, dtype=np.float64)
    out = out.reshape(out.shape[-2], out.shape[-1]) if out.ndim == 3 else out
    if layout == "auto":
        layout = "v5" if out.shape[0] >= out.shape[1] else "v8"
    if layout == "v8":
        rows = out.T
        cls = rows[:, 4:]
        scores = cls
    else:
        rows = out
        scores = rows[:, 4:5] * rows[:, 5:]
    best = np.argmax(scores, axis=1) if scores.shape[1] else np.zeros(rows.shape[0], dtype=np.int64)
    best_score = scores[np.arange(rows.shape[0]), best] if scores.shape[1] else np.zeros(rows.shape[0])
    return rows[:, :4], best_score, best.astype(np.int64)


def decode_detections(output: npt.ArrayLike, box: Letterbox, image_shape: tuple[int, int],
                      class_names: Sequence[str], confidence_threshold: float, nms_iou_threshold: float,
                      layout: Layout = "auto") -> tuple[Detection, ...]:
    """Detections in image pixels after the threshold, the letterbox inverse, clipping and per-class NMS."""
    xywh, scores, classes = yolo_candidates(output, layout)
    keep = scores >= confidence_threshold
    xywh, scores, classes = xywh[keep], scores[keep], classes[keep]
    if scores.size == 0:
        return ()
    h, w = image_shape
    cx = (xywh[:, 0] - box.pad_x) / box.scale
    cy = (xywh[:, 1] - box.pad_y) / box.scale
    half_w, half_h = xywh[:, 2] / box.scale / 2, xywh[:, 3] / box.scale / 2
    x0, x1 = np.clip(cx - half_w, -0.5, w - 0.5), np.clip(cx + half_w, -0.5, w - 0.5)
    y0, y1 = np.clip(cy - half_h, -0.5, h - 0.5), np.clip(cy + half_h, -0.5, h - 0.5)
    rects = [[float(a), float(b), float(c - a), float(d - b)] for a, b, c, d in zip(x0, y0, x1, y1, strict=True)]
    idx = cv2.dnn.NMSBoxesBatched(rects, scores.astype(float).tolist(), classes.tolist(),
                                  float(confidence_threshold), float(nms_iou_threshold))
    order = sorted(np.asarray(idx, dtype=np.int64).ravel().tolist(), key=lambda i: -scores[i])
    names = list(class_names)
    return tuple(Detection(names[c] if c < len(names) else str(c), float(scores[i]), float((x0[i] + x1[i]) / 2),
                           float((y0[i] + y1[i]) / 2), float(x1[i] - x0[i]), float(y1[i] - y0[i]))
                 for i in order for c in [int(classes[i])])


def detect_image(forward: Callable[[npt.NDArray[np.float32]], npt.NDArray[np.float32]],
                 pixels: npt.NDArray[np.uint8], config: DoorPoseConfig) -> tuple[Detection, ...]:
    """Letterbox an image, run the model's ``forward`` on it, and decode its boxes (module docstring)."""
    box = letterbox(pixels, config.input_size_px)
    return decode_detections(forward(box.blob), box, (int(pixels.shape[0]), int(pixels.shape[1])),
                             config.class_names, config.confidence_threshold, config.nms_iou_threshold,
                             config.yolo_layout)
