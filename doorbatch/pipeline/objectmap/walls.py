"""Wall M-step sub-steps of paper 001 Sec. V: the line by weighted least squares (eq. 8), then the number
and end points of its segments by an exact dynamic program over the rays that cross the line (eq. 9)."""

from __future__ import annotations

from dataclasses import dataclass

import numba  # type: ignore[import-untyped]
import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.objectmap.beams import BeamSet, beam_blocks
from doorbatch.pipeline.objectmap.model import WALL, ClassParams, ObjectMap
from doorbatch.pipeline.objectmap.sensor import FirstObjects, beam_logliks, cast_segments

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


def fit_line(points: FloatArray, weights: FloatArray) -> tuple[FloatArray, float]:
    """Eq. (8): the line n·p = β minimising Σ w (nᵀπ − β)² with ‖n‖ = 1 (weighted total least squares:
    β = nᵀ p̄ with p̄ the weighted mean, n the eigenvector of the smallest eigenvalue of the weighted
    scatter matrix)."""
    w = weights / np.sum(weights)
    mean = w @ points
    centered = points - mean
    scatter = (centered * w[:, None]).T @ centered
    _, vecs = np.linalg.eigh(scatter)
    normal = vecs[:, 0]
    return normal, float(normal @ mean)


@numba.njit(cache=True)  # type: ignore[misc]
def _segment_dp(s: FloatArray, gain: FloatArray, rho_length: float, start_cost: float) -> BoolArray:
    n = s.shape[0]
    c_in = np.empty(n)
    c_out = np.empty(n)
    from_in = np.zeros(n, dtype=np.bool_)  # c_in[k] came from c_in[k − 1] (segment continues)
    out_from_in = np.zeros(n, dtype=np.bool_)  # c_out[k] came from c_in[k − 1]
    c_in[0] = start_cost - gain[0]
    c_out[0] = 0.0
    for k in range(1, n):
        cont = c_in[k - 1] + rho_length * (s[k] - s[k - 1])
        new = c_out[k - 1] + start_cost
        if cont <= new:
            c_in[k] = cont - gain[k]
            from_in[k] = True
        else:
            c_in[k] = new - gain[k]
        if c_in[k - 1] < c_out[k - 1]:
            c_out[k] = c_in[k - 1]
            out_from_in[k] = True
        else:
            c_out[k] = c_out[k - 1]
    include = np.zeros(n, dtype=np.bool_)
    state = c_in[n - 1] < c_out[n - 1]
    for k in range(n - 1, -1, -1):
        include[k] = state
        if k == 0:
            break
        state = from_in[k] if state else out_from_in[k]
    return include


def segment_dp(s: FloatArray, gain: FloatArray, rho_length_per_m: float, start_cost: float
               ) -> tuple[FloatArray, float]:
    """Eq. (9) solved exactly: choose which crossing points lie on a segment.

    Points sorted by s; x_k ∈ {0, 1}. Cost = −Σ x_k Δ_k + ρL·Σ(length of segments) + start_cost·#segments,
    where a segment spans consecutive included points. Two costs are carried along the line (point in a
    segment or not), then a backward pass reads off the optimum. Returns the segments (K, 2) [s0, s1]
    (zero-length ones dropped) and the optimal cost (0 = no segment).
    """
    if s.shape[0] == 0:
        return np.zeros((0, 2)), 0.0
    order = np.argsort(s, kind="stable")
    ss, gg = s[order], gain[order]
    inc = _segment_dp(ss, gg, float(rho_length_per_m), float(start_cost))
    padded = np.concatenate([[False], inc, [False]])
    starts = np.flatnonzero(padded[1:-1] & ~padded[:-2])
    ends = np.flatnonzero(padded[1:-1] & ~padded[2:])
    segs = np.stack([ss[starts], ss[ends]], axis=1) if starts.size else np.zeros((0, 2))
    cost = float(-gg[inc].sum() + rho_length_per_m * np.sum(segs[:, 1] - segs[:, 0]) + start_cost * segs.shape[0])
    keep = segs[:, 1] > segs[:, 0]
    return segs[keep], cost


@dataclass(frozen=True)
class LineCrossings:
    """Beams whose ray crosses a line: beam index, distance t along the ray, position s along the line."""

    beam: IntArray
    t: FloatArray
    s: FloatArray


def ray_line_distances(beams: BeamSet, normal: FloatArray, offset: float) -> FloatArray:
    """t (B,): how far along each ray it meets the line n·p = β ((β − n·o)/(n·d); ±inf or nan when parallel,
    negative behind the origin)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t: FloatArray = (offset - beams.origin @ normal) / (beams.direction @ normal)
    return t


def rays_meeting_line_before(beams: BeamSet, normal: FloatArray, offset: float, limit: FloatArray) -> IntArray:
    """Indices of the beams whose ray meets the line n·p = β at 0 < t < ``limit`` (one limit per beam, e.g.
    the distance to its first object), in blocks of beams."""
    parts = []
    for sl in beam_blocks(len(beams)):
        t = ray_line_distances(beams.subset(sl), normal, offset)
        parts.append(np.flatnonzero(np.isfinite(t) & (t > 0.0) & (t < limit[sl])) + sl.start)
    return np.concatenate(parts) if parts else np.zeros(0, dtype=np.int64)


def line_crossings(beams: BeamSet, normal: FloatArray, offset: float, sigma: float) -> LineCrossings:
    """R_W: beams whose ray meets the line n·p = β before its measured end (+5σ) and within dmax (in blocks
    of beams, to bound the scratch memory on long logs)."""
    tangent = np.array([-normal[1], normal[0]])
    parts: list[tuple[IntArray, FloatArray, FloatArray]] = []
    for sl in beam_blocks(len(beams)):
        b = beams.subset(sl)
        t = ray_line_distances(b, normal, offset)
        ok = np.flatnonzero(np.isfinite(t) & (t > 0.0) & (t <= np.minimum(b.range_m + 5.0 * sigma, b.dmax)))
        parts.append((ok + sl.start, t[ok], (b.origin[ok] + t[ok, None] * b.direction[ok]) @ tangent))
    if not parts:
        return LineCrossings(np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0))
    return LineCrossings(*(np.concatenate(p) for p in zip(*parts, strict=True)))


def first_without(beams: BeamSet, first: FirstObjects, idx: IntArray, obj_map: ObjectMap, cls: int,
                  obj: int) -> tuple[FloatArray, IntArray]:
    """δ and class of the first object along beams ``idx`` when object (cls, obj) is left out."""
    delta = first.delta[idx].copy()
    kind = first.cls[idx].copy()
    redo = np.flatnonzero((kind == cls) & (first.obj[idx] == obj))
    delta[redo], kind[redo] = first_beyond(beams, idx[redo], np.zeros(redo.size), obj_map, cls, obj)
    return delta, kind


def first_beyond(beams: BeamSet, idx: IntArray, t: FloatArray, obj_map: ObjectMap, cls: int, obj: int
                 ) -> tuple[FloatArray, IntArray]:
    """δ and class of the first object along beams ``idx`` beyond distance ``t`` on each ray (objects nearer
    than t ignored; object (cls, obj) left out): what the ray would meet behind a line it crosses at t."""
    delta = np.full(idx.shape[0], np.inf)
    kind = np.full(idx.shape[0], -1, dtype=np.int64)
    if idx.size == 0:
        return delta, kind
    for p in range(beams.n_passes):
        sel = np.flatnonzero(beams.pass_index[idx] == p)
        if sel.size == 0:
            continue
        segs, seg_cls, seg_obj = obj_map.segments(p)
        keep = ~((seg_cls == cls) & (seg_obj == obj))
        if not keep.any():
            continue
        b = idx[sel]
        rng, hit = cast_segments(beams.origin[b] + t[sel, None] * beams.direction[b], beams.direction[b],
                                 segs[keep], None)
        delta[sel] = t[sel] + rng
        kind[sel] = np.where(hit >= 0, seg_cls[keep][np.maximum(hit, 0)], -1)
    return delta, kind


def crossing_gains(beams: BeamSet, idx: IntArray, t_obj: FloatArray, delta_other: FloatArray,
                   cls_other: IntArray, obj_cls: int, classes: ClassParams, lam: float, sigma: float) -> FloatArray:
    """Δ_k of eq. (9): the log-likelihood change of beam k when an object of class ``obj_cls`` is present
    where its ray crosses at t (δ⁺ = min(δ⁻, t)) rather than absent (δ⁻: the first other object).

    Deviation from the paper (one line): Δ is the change of the marginal log-likelihood log Σ_v p(d, l, v)
    instead of e·(log p⁺ − log p⁻), so that rays the current map calls noise (e ≈ 0) still count.
    Computed in blocks of beams (per-beam values) to bound the scratch memory on long logs."""
    gain = np.empty(idx.shape[0])
    for sl in beam_blocks(idx.shape[0]):
        b = beams.subset(idx[sl])
        nearer = t_obj[sl] < delta_other[sl]
        d_plus = np.where(nearer, t_obj[sl], delta_other[sl])
        c_plus = np.where(nearer, obj_cls, cls_other[sl])
        v_plus, inv = beam_logliks(b, d_plus, c_plus, classes, lam, sigma)
        v_minus, _ = beam_logliks(b, delta_other[sl], cls_other[sl], classes, lam, sigma)
        gain[sl] = np.logaddexp(v_plus, inv) - np.logaddexp(v_minus, inv)
    return gain


def wall_segments(beams: BeamSet, first: FirstObjects, obj_map: ObjectMap, j: int, normal: FloatArray,
                  offset: float, lam: float, sigma: float, rho_length_per_m: float, start_cost: float,
                  see_through_band_m: float | None = None) -> tuple[FloatArray, float]:
    """The segments of wall ``j`` (or a new wall, j = −1) on the line (normal, offset) by the DP, given
    every other object; and the DP's optimal cost (log-posterior change against no segment).

    ``see_through_band_m`` given: paper 001 Sec. VI's pseudo-E-step, "temporarily allowing for the detection
    of objects that are occluded": a ray that another object stops before the line is scored as if that
    object were absent (δ⁻ = the first object behind the line, δ⁺ = t) where its measured end lies more than
    the band behind that object (the ray went through it; a ray ending on it detected it, not what is
    behind). The cost is then not the log-posterior change; the caller must re-cut with occlusion and
    compare log posteriors."""
    cross = line_crossings(beams, normal, offset, sigma)
    if cross.beam.size == 0:
        return np.zeros((0, 2)), 0.0
    delta, kind = first_without(beams, first, cross.beam, obj_map, WALL, j)
    if see_through_band_m is not None:
        hidden = np.flatnonzero((delta < cross.t) & (beams.range_m[cross.beam] > delta + see_through_band_m))
        delta[hidden], kind[hidden] = first_beyond(beams, cross.beam[hidden], cross.t[hidden], obj_map, WALL, j)
    gain = crossing_gains(beams, cross.beam, cross.t, delta, kind, WALL, obj_map.classes, lam, sigma)
    return segment_dp(cross.s, gain, rho_length_per_m, start_cost)
