"""Quaternions (x, y, z, w) and homogeneous transforms, vectorized where it matters."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


def quaternion_to_matrix(q_xyzw: npt.ArrayLike) -> FloatArray:
    """Rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(q_xyzw, dtype=np.float64)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def transform_matrix(translation: npt.ArrayLike, q_xyzw: npt.ArrayLike) -> FloatArray:
    """4×4 homogeneous transform T with T·p = R(q)·p + t."""
    mat = np.eye(4)
    mat[:3, :3] = quaternion_to_matrix(q_xyzw)
    mat[:3, 3] = np.asarray(translation, dtype=np.float64)
    return mat


def transform_matrices(translations: npt.ArrayLike, q_xyzw: npt.ArrayLike) -> FloatArray:
    """(N, 4, 4) :func:`transform_matrix` of each row of ``translations`` (N, 3) and ``q_xyzw`` (N, 4), with the
    same arithmetic, element by element."""
    q = np.asarray(q_xyzw, dtype=np.float64).reshape(-1, 4)
    mats = np.zeros((q.shape[0], 4, 4))
    mats[:, 3, 3] = 1.0
    mats[:, :3, :3] = np.moveaxis(quaternion_to_matrix(q.T), -1, 0)  # (3, 3, N) from the (4, N) columns
    mats[:, :3, 3] = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    return mats


def invert_transform(mat: FloatArray) -> FloatArray:
    """Inverse of a rigid 4×4 transform: [Rᵀ, −Rᵀt]."""
    inv = np.eye(4)
    rot_t = mat[:3, :3].T
    inv[:3, :3] = rot_t
    inv[:3, 3] = -rot_t @ mat[:3, 3]
    return inv


def slerp(q0: FloatArray, q1: FloatArray, fraction: float) -> FloatArray:
    """Spherical linear interpolation between unit quaternions, along the shorter arc.

    q(f) = sin((1−f)θ)/sin θ · q0 + sin(fθ)/sin θ · q1, with cos θ = |q0·q1| (q1 negated when q0·q1 < 0).
    """
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 1.0 - 1e-12:
        out = q0 + fraction * (q1 - q0)
        return np.asarray(out / np.linalg.norm(out), dtype=np.float64)
    theta = np.arccos(min(dot, 1.0))
    s = np.sin(theta)
    out = (np.sin((1.0 - fraction) * theta) * q0 + np.sin(fraction * theta) * q1) / s
    return np.asarray(out, dtype=np.float64)


def yaw_of_matrix(mat: FloatArray) -> float:
    """Heading of a rotation (the angle of its x axis projected onto the xy plane)."""
    return float(np.arctan2(mat[1, 0], mat[0, 0]))


def wrap_angle(angle: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """Wrap angles to (−π, π]."""
    a = np.asarray(angle, dtype=np.float64)
    wrapped = np.mod(a + np.pi, 2 * np.pi) - np.pi
    return np.where(wrapped == -np.pi, np.pi, wrapped)
