"""Door leaf geometry for the RBPF (paper 000, Sec. IV): leaf end points, point-to-leaf distances and their
derivative with respect to the door angle, and a cheap reach test that skips doors far from the scan.

A door k is a segment from its hinge h_k to its free end h_k + L_k·u(a), u(a) = (cos(θ_k + a), sin(θ_k + a)),
with θ_k the door's ``closed_yaw`` and a its opening angle (CCW positive), as in :class:`doorbatch.maps.DoorSet`.

For a point p, with v = p − h, t = v·u (position of the foot along the leaf), s = u × v = u_x v_y − u_y v_x
(signed perpendicular offset, positive on the CCW side) and t_c = clip(t, 0, L), the distance is
d = |v − t_c·u| and its derivative with respect to a is

    ∂d/∂a = −t_c · s / d,

which covers the three cases at once: the foot on the leaf (d = |s|, ∂d/∂a = ∓t, minus the distance along the
leaf from the hinge when p lies CCW of the leaf: turning the leaf CCW brings it closer); the hinge closest
(t ≤ 0, t_c = 0, the distance does not depend on a); the free end closest (t ≥ L: d = |p − e| with
e = h + L·u, ∂d/∂a = −(p − e)·L·u⊥ / d and (p − e)·u⊥ = u × (v − L·u) = s). |∂d/∂a| ≤ L everywhere.

On the leaf itself (d = 0) the distance has a kink; there J = −t_c, its derivative on the CCW side, so that J²
(what eq. (6) uses: the signed offset s is smooth in a with ∂s/∂a = −t) is continuous across the leaf.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.maps import DoorSet

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
RealArray = npt.NDArray[np.floating[Any]]

# Particle rows per chunk in :func:`point_to_leaf_distance` are chosen so that a chunk holds about this many
# (particle, beam, door) elements: float64 temporaries of ~8 MB each, whatever N is.
CHUNK_ELEMENTS = 1 << 20


def leaf_directions(doors: DoorSet, angles: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """cos and sin of the leaf direction closed_yaw + angle, each shaped like ``angles`` (..., D)."""
    phi = np.asarray(doors.closed_yaw, dtype=np.float64) + np.asarray(angles, dtype=np.float64)
    return np.cos(phi), np.sin(phi)


def leaf_endpoints(doors: DoorSet, angles: npt.ArrayLike) -> FloatArray:
    """Free ends of the leaves, h + L·(cos(θ + a), sin(θ + a)).

    Args:
        doors: D doors.
        angles: (N, D) opening angles (rad, relative to closed_yaw, CCW positive); any (..., D) works.

    Returns:
        (N, D, 2) float64 map-frame points.
    """
    c, s = leaf_directions(doors, angles)
    length = np.asarray(doors.length, dtype=np.float64)
    hinge = np.asarray(doors.hinge, dtype=np.float64)
    return np.stack([hinge[:, 0] + length * c, hinge[:, 1] + length * s], axis=-1)


def point_to_leaf_distance(points: npt.ArrayLike, doors: DoorSet, angles: npt.ArrayLike,
                           dtype: type[np.float32] | type[np.float64] = np.float32) -> tuple[RealArray, RealArray]:
    """Distance of each beam end point to each door leaf, and its derivative with respect to the door angle.

    The arithmetic is float64, in chunks of particles (about :data:`CHUNK_ELEMENTS` elements each), so the
    peak memory is the two outputs plus a few tens of MB: 10,000 particles × 60 beams × 10 doors give two
    24 MB float32 arrays. Restrict the doors first with :func:`doors_in_reach` and :func:`subset_doors`.

    Args:
        points: (N, B, 2) beam end points in the map frame, per particle.
        doors: D doors.
        angles: (N, D) door angles per particle (the RBPF uses each particle's door mean).
        dtype: Output dtype (float32 by default; float64 for finite-difference checks).

    Returns:
        ``(dist, jac)``, each (N, B, D): d ≥ 0 (m) and ∂d/∂a (m/rad), see the module docstring (J = −t_c
        on the leaf, where d = 0).
    """
    pts = np.asarray(points, dtype=np.float64)
    ang = np.asarray(angles, dtype=np.float64)
    n, b = pts.shape[0], pts.shape[1]
    d = len(doors)
    dist = np.empty((n, b, d), dtype=dtype)
    jac = np.empty((n, b, d), dtype=dtype)
    if n == 0 or b == 0 or d == 0:
        return dist, jac
    hinge = np.asarray(doors.hinge, dtype=np.float64)
    length = np.asarray(doors.length, dtype=np.float64)
    ux, uy = leaf_directions(doors, ang)  # (N, D)
    step = max(1, CHUNK_ELEMENTS // (b * d))
    for lo in range(0, n, step):  # chunks of particles (memory), not a per-particle loop
        sl = slice(lo, min(n, lo + step))
        vx = pts[sl, :, 0, None] - hinge[:, 0]  # (n, B, D)
        vy = pts[sl, :, 1, None] - hinge[:, 1]
        cx, cy = ux[sl, None, :], uy[sl, None, :]
        t_c = np.clip(vx * cx + vy * cy, 0.0, length)
        s = cx * vy - cy * vx
        dist_c = np.hypot(vx - t_c * cx, vy - t_c * cy)
        with np.errstate(divide="ignore", invalid="ignore"):
            jac_c = np.where(dist_c > 0.0, -t_c * s / dist_c, -t_c)
        dist[sl] = dist_c
        jac[sl] = jac_c
    return dist, jac


def doors_in_reach(doors: DoorSet, xy: npt.ArrayLike, margin_m: float) -> BoolArray:
    """Doors whose leaf can come within ``margin_m`` of some of the points, whatever its angle.

    The leaf lies in the disc of radius L around the hinge, so a door is kept when its hinge is within
    L + margin of the axis-aligned bounding box of ``xy``: conservative (never drops a door that matters),
    O(points + doors). With the beam end points and margin = the likelihood field's distance cap, it keeps
    exactly the doors that :mod:`door_likelihood` could associate; with the particle positions and
    margin = the laser's maximum range, the doors the scan can see.

    Args:
        doors: D doors.
        xy: (..., 2) points (non-finite ones are ignored).
        margin_m: Extra distance (m).

    Returns:
        (D,) bool.
    """
    pts = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if pts.shape[0] == 0:
        return np.zeros(len(doors), dtype=bool)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    hinge = np.asarray(doors.hinge, dtype=np.float64)
    gap = np.maximum(np.maximum(lo - hinge, hinge - hi), 0.0)  # (D, 2) per-axis distance to the box
    reach = np.asarray(doors.length, dtype=np.float64) + margin_m
    return np.asarray(np.hypot(gap[:, 0], gap[:, 1]) <= reach, dtype=np.bool_)


def subset_doors(doors: DoorSet, index: npt.ArrayLike) -> DoorSet:
    """The doors at ``index`` (an int array or a (D,) bool mask), as a new :class:`DoorSet`."""
    idx = np.asarray(index)
    if idx.dtype == np.bool_:
        idx = np.flatnonzero(idx)
    return DoorSet(hinge=np.asarray(doors.hinge)[idx], length=np.asarray(doors.length)[idx],
                   closed_yaw=np.asarray(doors.closed_yaw)[idx], angle_min=np.asarray(doors.angle_min)[idx],
                   angle_max=np.asarray(doors.angle_max)[idx], door_id=doors.ids[idx])


_COMPILED: dict[str, Any] = {}


def jit_kernel(fn: Callable[..., Any]) -> Callable[..., Any] | None:
    """``fn`` compiled with numba (nopython, cached on disk, compiled on first use), or None without numba.

    The door modules keep a NumPy reference of every kernel and fall back to it when this returns None.
    """
    key = f"{fn.__module__}.{fn.__qualname__}"
    if key not in _COMPILED:
        try:
            import numba  # type: ignore[import-untyped,unused-ignore]
        except ImportError:
            _COMPILED[key] = None
        else:
            _COMPILED[key] = numba.njit(cache=True, nogil=True)(fn)
    kernel: Callable[..., Any] | None = _COMPILED[key]
    return kernel


def with_closed_in_range(doors: DoorSet) -> DoorSet:
    """The doors with every opening range widened to include the closed angle 0: [min(angle_min, 0),
    max(angle_max, 0)]. Any door can close; a door the map saw only open (the em stage's never-moved doors
    carry a zero-width range at the angle mapping saw, e.g. [−90°, −90°]) would otherwise have its closed leaf
    rejected by the RBPF's orientation gate (range ± door_angle_margin_deg) and never be tracked closed."""
    return DoorSet(doors.hinge, doors.length, doors.closed_yaw, np.minimum(doors.angle_min, 0.0),
                   np.maximum(doors.angle_max, 0.0), doors.door_id)


def with_unmoved_swing(doors: DoorSet, unmoved: npt.ArrayLike, swing_rad: float, side_known_rad: float) -> DoorSet:
    """The doors with each never-moved door's range widened to the swing a hinged door has.

    A door that never moved while mapping (the em stage's: doors.parquet ``moved`` false) has a zero-width
    range, the one angle the passes saw, which says nothing of how far it opens; the RBPF would take its open
    leaf for clutter on a day someone opens it. Seen open at a (|a| > ``side_known_rad``), it opens to that
    side: [lo, hi] ∪ [0, sign(a)·swing]. Seen closed, the side is unknown: [−swing, swing]. Moved doors keep
    their observed range (paper 000 Sec. III); swing 0 leaves every range as it is.

    Expert choice (the papers give never-moved doors no range): the swing of an office door, 90° by default,
    short of the wall beyond the hinge at 180°, whose segment would otherwise pass the association's gates.
    """
    unmoved = np.asarray(unmoved, dtype=np.bool_)
    if swing_rad <= 0.0 or not unmoved.any():
        return doors
    lo = np.asarray(doors.angle_min, dtype=np.float64)
    hi = np.asarray(doors.angle_max, dtype=np.float64)
    seen = (lo + hi) / 2
    unknown = hinge_unknown(unmoved, doors, side_known_rad)
    opens_pos = unmoved & ~unknown & (seen > 0.0)
    opens_neg = unmoved & ~unknown & (seen < 0.0)
    hi = np.where(opens_pos | unknown, np.maximum(hi, swing_rad), hi)
    lo = np.where(opens_neg | unknown, np.minimum(lo, -swing_rad), lo)
    return DoorSet(doors.hinge, doors.length, doors.closed_yaw, np.minimum(lo, 0.0), np.maximum(hi, 0.0),
                   doors.door_id)


def hinge_unknown(unmoved: npt.ArrayLike, doors: DoorSet, side_known_rad: float) -> npt.NDArray[np.bool_]:
    """(D,) whether each door never moved while mapping and was seen closed (within ``side_known_rad``): such a
    leaf shows no hinge, both its ends explain the same hits, so the map's hinge may be its free end."""
    seen = (np.asarray(doors.angle_min, dtype=np.float64) + np.asarray(doors.angle_max, dtype=np.float64)) / 2
    return np.asarray(np.asarray(unmoved, dtype=np.bool_) & (np.abs(seen) <= side_known_rad), dtype=np.bool_)


def other_end(doors: DoorSet) -> DoorSet:
    """The doors hinged at their free ends instead: hinge h + L·(cos ψ, sin ψ), closed direction ψ + π, range
    the closed angle alone; door ids kept."""
    n = len(doors)
    tip = leaf_endpoints(doors, np.zeros(n))
    return DoorSet(tip, doors.length, wrap_angle(np.asarray(doors.closed_yaw) + np.pi), np.zeros(n), np.zeros(n),
                   doors.ids)

