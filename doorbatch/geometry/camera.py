"""The pinhole camera of a sensor_msgs/CameraInfo: projection, pixel rays and bearings, laser points in the camera.

Frames follow REP 103's optical convention: z forward, x right, y down. With K = [[f_x, 0, c_x],
[0, f_y, c_y], [0, 0, 1]] and distortion D, a point (X, Y, Z) with Z > 0 projects to

    (x, y) = (X/Z, Y/Z),  (x_d, y_d) = distort_D(x, y),  u = f_x x_d + c_x,  v = f_y y_d + c_y

(OpenCV's ``projectPoints``; the centre of pixel column i is u = i). The inverse, a pixel's ray, is the
undistorted normalized point (x, y, 1) (OpenCV's ``undistortPoints``). ``plumb_bob`` (k1, k2, t1, t2, k3) and
``rational_polynomial`` (8 coefficients) are OpenCV's models; ``equidistant`` uses ``cv2.fisheye``.

The *bearing* of a ray is its angle in the optical x–z plane, β = atan2(x, z): 0 on the optical axis,
increasing to the right (with the pixel column). For a level camera that plane is horizontal, so bearings
of pixels and of laser points (moved into the optical frame by TF) can be compared directly (paper 003,
Sec. III-B); a tilted camera's rays and points are turned into its level frame first (:func:`level_rotation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import numpy.typing as npt

from doorbatch.errors import LogContentError
from doorbatch.geometry.laser import beam_masks
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.records import CameraInfo, Scan

FloatArray = npt.NDArray[np.float64]

SUPPORTED_DISTORTION_MODELS = ("plumb_bob", "rational_polynomial", "equidistant", "none", "")
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)


@dataclass(frozen=True)
class PinholeCamera:
    """Intrinsics K (3×3), distortion coefficients D and the image size, in the optical frame ``frame_id``."""

    width: int
    height: int
    k: FloatArray  # (3, 3)
    d: FloatArray  # (n,) OpenCV order; empty: no distortion
    distortion_model: str
    frame_id: str

    @property
    def fx(self) -> float:
        """Focal length f_x (px)."""
        return float(self.k[0, 0])

    @property
    def fy(self) -> float:
        """Focal length f_y (px)."""
        return float(self.k[1, 1])

    @property
    def cx(self) -> float:
        """Principal point c_x (px)."""
        return float(self.k[0, 2])

    @property
    def cy(self) -> float:
        """Principal point c_y (px)."""
        return float(self.k[1, 2])

    @property
    def is_fisheye(self) -> bool:
        """Whether D is the equidistant (Kannala-Brandt) model."""
        return self.distortion_model == "equidistant"


def camera_from_info(info: CameraInfo) -> PinholeCamera:
    """The camera of a CameraInfo record.

    Raises:
        LogContentError: an unknown distortion model, a singular K, or a non-positive image size.
    """
    model = info.distortion_model.strip().lower()
    if model not in SUPPORTED_DISTORTION_MODELS:
        raise LogContentError(f"camera_info distortion model {info.distortion_model!r} is not supported "
                              f"(supported: {', '.join(m for m in SUPPORTED_DISTORTION_MODELS if m)})")
    k = np.asarray(info.k, dtype=np.float64).reshape(3, 3)
    if k[0, 0] <= 0.0 or k[1, 1] <= 0.0:
        raise LogContentError(f"camera_info K has non-positive focal lengths ({k[0, 0]}, {k[1, 1]})")
    if info.width <= 0 or info.height <= 0:
        raise LogContentError(f"camera_info image size {info.width}x{info.height} is empty")
    d = np.asarray(info.d, dtype=np.float64).ravel()
    if model in ("none", "") or not np.any(d):
        d = np.zeros(0)
        model = "none"
    elif model == "equidistant":
        d = np.resize(d, 4)
    return PinholeCamera(int(info.width), int(info.height), k, d, model, info.frame_id)


def project_points(camera: PinholeCamera, points_cam: npt.ArrayLike) -> FloatArray:
    """Pixels (N, 2) of points (N, 3) in the optical frame; NaN rows for points with Z ≤ 0 or not finite.

    u = f_x·distort(X/Z, Y/Z)_x + c_x, v = f_y·distort(X/Z, Y/Z)_y + c_y (module docstring).
    """
    pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    out = np.full((pts.shape[0], 2), np.nan)
    front = np.isfinite(pts).all(axis=1) & (pts[:, 2] > 0.0)
    if not front.any():
        return out
    obj = np.ascontiguousarray(pts[front]).reshape(-1, 1, 3)
    zero = np.zeros(3)
    if camera.is_fisheye:
        px, _ = cv2.fisheye.projectPoints(obj, zero, zero, camera.k, camera.d)
    else:
        px, _ = cv2.projectPoints(obj, zero, zero, camera.k, camera.d if camera.d.size else None)
    out[front] = px.reshape(-1, 2)
    return out


def _undistort_points(px: FloatArray, k: FloatArray, d: FloatArray) -> FloatArray:
    """Normalized undistorted points, iterated to 1e-12 (OpenCV's default stops after 5 iterations, ~1e-6
    off near the border): ``undistortPointsIter`` in OpenCV 4, the ``criteria`` argument in OpenCV 5."""
    coeffs = d if d.size else None
    iterate = getattr(cv2, "undistortPointsIter", None)
    if iterate is not None:
        return np.asarray(iterate(px, k, coeffs, None, None, _UNDISTORT_CRITERIA), dtype=np.float64)
    return np.asarray(cv2.undistortPoints(px, k, coeffs, criteria=_UNDISTORT_CRITERIA), dtype=np.float64)


def pixel_rays(camera: PinholeCamera, pixels: npt.ArrayLike) -> FloatArray:
    """Rays (N, 3) in the optical frame through pixels (N, 2): the undistorted normalized point (x, y, 1).

    Not unit length: the ray parameter is the depth Z. Inverse of :func:`project_points` up to scale.
    """
    px = np.ascontiguousarray(np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2))
    if px.shape[0] == 0:
        return np.zeros((0, 3))
    if camera.is_fisheye:
        xy = cv2.fisheye.undistortPoints(px, camera.k, camera.d)
    else:
        xy = _undistort_points(px, camera.k, camera.d)
    xy = xy.reshape(-1, 2)
    return np.concatenate([xy, np.ones((xy.shape[0], 1))], axis=1)


def level_rotation(camera_to_base: npt.ArrayLike) -> FloatArray:
    """R (3×3) taking optical-frame vectors into the *level* camera frame: z the optical axis projected onto
    base_link's floor plane, y down (−z of base_link), x = y × z (right); the identity for a level camera. There
    pixel and laser bearings are horizontal whatever the camera's pitch and roll (paper 003 assumes a level camera;
    a manipulation robot's looks down). Raises ValueError for an optical axis within 1° of vertical."""
    rot = np.asarray(camera_to_base, dtype=np.float64)[:3, :3]
    forward = np.array([rot[0, 2], rot[1, 2], 0.0])
    norm = float(np.hypot(forward[0], forward[1]))
    if norm < math.sin(math.radians(1.0)):
        raise ValueError("the camera's optical axis is vertical: no horizontal bearing")
    forward /= norm
    down = np.array([0.0, 0.0, -1.0])
    return np.asarray(np.stack([np.cross(down, forward), down, forward]) @ rot, dtype=np.float64)


def box_edge_bearings(camera: PinholeCamera, left_px: float, right_px: float, top_px: float, bottom_px: float,
                      level: npt.ArrayLike | None = None, rows: int = 33) -> tuple[float, float]:
    """Horizontal bearings (rad, positive right) of a box's left and right edges in the level frame (``level``,
    :func:`level_rotation`; None: the camera is level).

    A door edge is a vertical line in the world: every pixel of its image has one level bearing, and the box's edge
    column touches that image where it reaches farthest out (the top or bottom end under a tilted camera, the
    horizon row under barrel distortion, the ends under pincushion) and lies outside it elsewhere. So the edge's
    bearing is the innermost of the column's, over ``rows`` rows from top to bottom and the horizon row c_y: the
    largest on the left, the smallest on the right. A level undistorted camera gives every row the same.
    """
    v = np.unique(np.clip(np.append(np.linspace(top_px, bottom_px, rows), camera.cy), top_px, bottom_px))
    px = np.concatenate([np.stack([np.full_like(v, left_px), v], 1), np.stack([np.full_like(v, right_px), v], 1)])
    rays = pixel_rays(camera, px)
    if level is not None:
        rays = rays @ np.asarray(level, dtype=np.float64).T
    beta = np.arctan2(rays[:, 0], rays[:, 2])
    return float(beta[: v.size].max()), float(beta[v.size:].min())


def point_bearings(points_cam: npt.ArrayLike) -> FloatArray:
    """Bearings β = atan2(X, Z) (rad, positive right) of points (N, 3) in the optical frame."""
    pts = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    return np.arctan2(pts[:, 0], pts[:, 2])


def transform_points(transform: FloatArray, points: npt.ArrayLike) -> FloatArray:
    """Points (N, 3) moved by a 4×4 rigid transform: p' = R·p + t."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return np.asarray(pts @ transform[:3, :3].T + transform[:3, 3], dtype=np.float64)


def scan_points_3d(scan: Scan) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """Hit end points (N, 3) of a scan in its laser frame, (r cos θ, r sin θ, 0), and their beam indices.

    A hit: finite and range_min ≤ r < range_max (DESIGN.md laser conventions); other beams are dropped.
    """
    r = scan.ranges.astype(np.float64)
    idx = np.flatnonzero(beam_masks(scan)[0])
    a = scan.angles[idx]
    pts = np.stack([r[idx] * np.cos(a), r[idx] * np.sin(a), np.zeros(idx.size)], axis=1)
    return pts, idx.astype(np.int64)


def scan_in_camera(scan: Scan, tf: TfBuffer, camera_frame: str) -> tuple[FloatArray, npt.NDArray[np.int64]]:
    """A scan's hit points (N, 3) in the camera's optical frame at the scan's stamp, and their beam indices.

    Raises:
        TransformError: no transform from the laser frame to the camera frame at the scan's stamp.
    """
    pts, idx = scan_points_3d(scan)
    return transform_points(tf.lookup(camera_frame, scan.frame_id, scan.stamp_ns, hold_constant=True), pts), idx


def in_image(camera: PinholeCamera, pixels: FloatArray) -> npt.NDArray[np.bool_]:
    """Mask of pixels (N, 2) inside the image, [−0.5, W − 0.5) × [−0.5, H − 0.5) (NaN: outside)."""
    u, v = pixels[:, 0], pixels[:, 1]
    with np.errstate(invalid="ignore"):
        return (u >= -0.5) & (u < camera.width - 0.5) & (v >= -0.5) & (v < camera.height - 0.5)
