"""The structure search of paper 001 Sec. VI: walls from a Hough transform, doors from motion and from
colour; each new object is fitted after a pseudo-E-step and kept only if the log posterior improves.

Outline::

    walls  = Hough lines at the dominant orientations, each: pseudo-E-step → line fit (eq. 8) → DP (eq. 9)
    EM
    repeat: door candidates from motion (wall pieces crossed by rays of some pass; leaf-like segments of
            one pass crossed by rays of another) and colour (wall runs better explained by the door colour)
            each: per-pass angles by a pseudo-E-step search → hinge/angles (eq. 10) → walls re-cut (eq. 9)
            → kept if the log posterior rises;  EM;  doors that no longer pay terminated
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from doorbatch.config import ObjectMapConfig
from doorbatch.pipeline.gridmap.doors import cluster_points
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.colors import class_color_loglik
from doorbatch.pipeline.objectmap.doors import fit_hinge_angles, initial_angles, rays_near
from doorbatch.pipeline.objectmap.em import EmTrace, MapState, evaluate, run_em
from doorbatch.pipeline.objectmap.hough import hough_lines
from doorbatch.pipeline.objectmap.model import DOOR, WALL, ClassParams, Door, ObjectMap, Wall
from doorbatch.pipeline.objectmap.prior import log_prior
from doorbatch.pipeline.objectmap.sensor import FirstObjects, cast_segments, e_step
from doorbatch.pipeline.objectmap.walls import (
    crossing_gains,
    first_without,
    fit_line,
    line_crossings,
    rays_meeting_line_before,
    segment_dp,
    wall_segments,
)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class DoorCandidate:
    """A proposed hinge and the leaf direction to assume where a pass does not show the leaf."""

    hinge: FloatArray
    fallback_yaw: float
    source: str  # "motion", "color" or "grid" (a seed: search_structure)
    support: int


def initial_classes(beams: BeamSet, config: ObjectMapConfig) -> ClassParams:
    """Class parameters before learning: the configured width; both colours the overall colour spread."""
    has = config.use_color and beams.has_color
    if not has:
        return ClassParams(config.door_width_init_m)
    col = beams.color[np.isfinite(beams.color[:, 0])]
    mean = np.tile(col.mean(axis=0), (2, 1))
    var = np.tile(np.maximum(col.var(axis=0), config.color_var_floor), (2, 1))
    return ClassParams(config.door_width_init_m, mean, var, True)


def _add_to_first(beams: BeamSet, first: FirstObjects, segs: FloatArray, cls: int, obj: int) -> FirstObjects:
    rng, idx = cast_segments(beams.origin, beams.direction, segs)
    closer = (idx >= 0) & (rng < first.delta)
    return FirstObjects(np.where(closer, rng, first.delta), np.where(closer, cls, first.cls),
                        np.where(closer, obj, first.obj))


def propose_walls(beams: BeamSet, obj_map: ObjectMap, config: ObjectMapConfig) -> ObjectMap:
    """Walls from the Hough transform of all points, strongest first. Each proposal: a pseudo-E-step
    (points within ``pseudo_e_sigmas``·σ of the line, occlusion ignored, weighted by the Gaussian),
    two line fits (eq. 8), then the DP (eq. 9) given the walls already accepted; kept when the DP's gain
    pays for the line's two parameters."""
    pts = beams.points[beams.hit]
    sigma = config.sigma_m
    band = config.pseudo_e_sigmas * sigma
    state = evaluate(beams, obj_map, config)
    first = state.first
    walls = list(obj_map.walls)
    for normal, offset, _ in hough_lines(pts, config.hough_step_deg, config.hough_offset_bin_m,
                                         config.hough_orientation_share, config.hough_min_points,
                                         config.max_wall_proposals):
        for _ in range(2):
            r = pts @ normal - offset
            sel = np.abs(r) < band + config.hough_offset_bin_m
            if int(sel.sum()) < config.hough_min_points:
                break
            normal, offset = fit_line(pts[sel], np.exp(-0.5 * (r[sel] / sigma) ** 2) + 1e-12)
        else:
            if any(abs(float(normal @ w.normal)) > np.cos(np.deg2rad(config.collinear_angle_deg))
                   and abs(offset * np.sign(normal @ w.normal) - w.offset) < band for w in walls):
                continue
            current = replace(obj_map, walls=walls)
            segs, cost = wall_segments(beams, first, current, -1, normal, offset, config.validity_prior, sigma,
                                       config.rho_length_per_m, 2.0 * config.rho_static)
            if segs.shape[0] and cost + 2.0 * config.rho_static < 0.0:
                wall = Wall(normal, offset, segs)
                walls.append(wall)
                first = _add_to_first(beams, first, wall.endpoints(), WALL, len(walls) - 1)
    return replace(obj_map, walls=walls)


def _intervals(s: FloatArray, gap: float, min_count: int, min_extent: float) -> list[tuple[float, float, int]]:
    """Runs of sorted positions with gaps ≤ ``gap``: (start, end, count) of those big enough."""
    if s.size == 0:
        return []
    s = np.sort(s)
    cuts = np.flatnonzero(np.diff(s) > gap)
    starts = np.concatenate([[0], cuts + 1])
    ends = np.concatenate([cuts, [s.size - 1]])
    return [(float(s[a]), float(s[b]), int(b - a + 1)) for a, b in zip(starts, ends, strict=True)
            if b - a + 1 >= min_count and s[b] - s[a] >= min_extent]


def _both_ends(a: FloatArray, b: FloatArray, source: str, support: int) -> list[DoorCandidate]:
    yaw_ab = float(np.arctan2(*(b - a)[::-1]))
    return [DoorCandidate(a, yaw_ab, source, support), DoorCandidate(b, yaw_ab + np.pi, source, support)]


def motion_candidates(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> list[DoorCandidate]:
    """Doors from motion (Sec. VI): wall pieces that rays of some pass cross (the ray ends well beyond the
    wall: the piece was absent in that pass, present in the others that built it). The hinge is at one
    end of the crossed piece, the closed leaf along the wall toward the other end (both ends are tried);
    and (2) leaf-like pieces of one pass crossed by rays of another (:func:`_leaf_candidates`)."""
    out: list[DoorCandidate] = []
    first, obj_map = state.first, state.obj_map
    through = beams.range_m > first.delta + config.through_margin_m
    for j, wall in enumerate(obj_map.walls):
        for t in range(beams.n_passes):
            sel = through & (first.cls == WALL) & (first.obj == j) & (beams.pass_index == t)
            if int(sel.sum()) < config.min_crossing_rays:
                continue
            s = (beams.origin[sel] + first.delta[sel, None] * beams.direction[sel]) @ wall.tangent
            for a, b, n in _intervals(s, config.candidate_cluster_m, config.min_crossing_rays,
                                      config.min_doorway_m):
                base = wall.offset * wall.normal
                out += _both_ends(base + a * wall.tangent, base + b * wall.tangent, "motion", n)
    return out + _leaf_candidates(beams, state, config)


def _leaf_candidates(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> list[DoorCandidate]:
    """Straight, door-sized pieces of one pass's points that the map does not explain (they stand in front
    of the modelled object) and that rays of another pass cross: a leaf that was elsewhere then."""
    out: list[DoorCandidate] = []
    first = state.first
    pts = beams.points
    poor = beams.hit & (state.e < 0.5) & (beams.range_m < np.minimum(first.delta, beams.dmax)
                                         - config.through_margin_m)
    for t in range(beams.n_passes):
        sel = np.flatnonzero(poor & (beams.pass_index == t))
        if sel.size < config.min_crossing_rays:
            continue
        labels = cluster_points(pts[sel], config.candidate_cluster_m)
        others = np.flatnonzero(beams.pass_index != t)
        for lab in np.unique(labels):
            members = sel[labels == lab]
            if members.size < config.min_crossing_rays:
                continue
            normal, offset = fit_line(pts[members], np.ones(members.size))
            tangent = np.array([-normal[1], normal[0]])
            along = pts[members] @ tangent
            rms = float(np.sqrt(np.mean((pts[members] @ normal - offset) ** 2)))
            if rms > 2.0 * config.sigma_m or not (config.min_leaf_piece_m <= float(np.ptp(along))
                                                  <= config.door_width_max_m + 2.0 * config.sigma_m):
                continue
            a = offset * normal + along.min() * tangent
            b = offset * normal + along.max() * tangent
            rng, idx = cast_segments(beams.origin[others], beams.direction[others], np.stack([a, b])[None])
            crossed = int(np.sum((idx >= 0) & (beams.range_m[others] > rng + config.through_margin_m)))
            if crossed >= config.min_crossing_rays:
                out += _both_ends(a, b, "motion", crossed)
    return out


def color_candidates(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> list[DoorCandidate]:
    """Doors from colour (Sec. VI): runs along a wall whose beams' colours are better explained by the
    door class than by the wall class, at least half a door width long; in a run longer than 1.5 widths
    (overlapping colour classes), the door-wide window with the largest summed log-likelihood ratio. A run
    is proposed only where its colour differs from the walls beside it (:func:`color_contrast`)."""
    obj_map = state.obj_map
    classes = obj_map.classes
    if not classes.has_color:
        return []
    col = beams.color
    # the range must fit the wall (the colour may not: under the wall class a door's colour is 'invalid')
    fits = np.abs(beams.range_m - state.first.delta) < config.pseudo_e_sigmas * config.sigma_m
    ok = beams.hit & np.isfinite(col[:, 0]) & (state.first.cls == WALL) & fits
    ratio = np.zeros(col.shape[0])
    ratio[ok] = class_color_loglik(col[ok], DOOR, classes) - class_color_loglik(col[ok], WALL, classes)
    door_like = ok & (ratio > 0.0)
    out: list[DoorCandidate] = []
    width = classes.door_width_m
    ok_points, ok_colors, ok_obj = beams.points[ok], col[ok], state.first.obj[ok]
    for j, wall in enumerate(obj_map.walls):
        sel = door_like & (state.first.obj == j)
        if int(sel.sum()) < config.min_crossing_rays:
            continue
        s = beams.points[sel] @ wall.tangent
        on_wall = ok & (state.first.obj == j)
        s_all = beams.points[on_wall] @ wall.tangent
        order = np.argsort(s_all)
        s_all, csum = s_all[order], np.concatenate([[0.0], np.cumsum(ratio[on_wall][order])])
        base = wall.offset * wall.normal
        col_all = col[on_wall][order]
        gap = config.candidate_cluster_m
        for a, b, n in _intervals(s, gap, config.min_crossing_rays, 0.5 * width):
            # the door-wide window most door-like: the candidate in a long run (colours overlap), and where the
            # colour is compared with the wall beside it in any run longer than a door
            wa, wb = _most_door_like_window(s_all, csum, a, b, width) if b - a > width else (a, b)
            if b - a > 1.5 * width:
                a, b = wa, wb
            inside = (s_all >= wa) & (s_all <= wb)
            # beside: a door width either side of the window, outside the run when the run is the candidate
            beside_s = ((s_all >= wa - width) & (s_all < min(wa, a) - gap)) | (
                (s_all > max(wb, b) + gap) & (s_all <= wb + width))
            beside = col_all[beside_s]
            if beside.shape[0] < config.min_crossing_rays:  # the run is its wall (a leaf that never moved, standing
                # open): the other walls' beams within a door width of its ends
                ends = base + np.array([wa, wb])[:, None] * wall.tangent
                near = np.min(np.linalg.norm(ok_points[:, None, :] - ends[None], axis=2), axis=1) <= width
                beside = ok_colors[near & (ok_obj != j)]
            if color_contrast(col_all[inside], beside, config) < config.color_contrast_min_sigmas:
                continue  # no colour edge at its ends: a differently painted wall, or classes that overlap
            out += _both_ends(base + a * wall.tangent, base + b * wall.tangent, "color", n)
    return out


def _most_door_like_window(s_sorted: FloatArray, ratio_cumsum: FloatArray, a: float, b: float, width: float
                           ) -> tuple[float, float]:
    """The window [start, start + width] within [a, b] whose beams (positions ``s_sorted``, cumulative colour
    log-likelihood ratios ``ratio_cumsum``, with a leading 0) sum to the largest door-over-wall ratio."""
    starts = s_sorted[(s_sorted >= a) & (s_sorted <= b - width)]
    if starts.size == 0:
        return a, b
    score = (ratio_cumsum[np.searchsorted(s_sorted, starts + width, "right")]
             - ratio_cumsum[np.searchsorted(s_sorted, starts)])
    start = float(starts[int(np.argmax(score))])
    return start, start + width


def color_contrast(inside: FloatArray, beside: FloatArray, config: ObjectMapConfig) -> float:
    """How far a run's mean chromaticity lies from that of the same wall beside it, in pooled standard
    deviations: sqrt(Σ_c (μ_in,c − μ_beside,c)² / ((σ²_in,c + σ²_beside,c) / 2)) over the chromaticities
    c = r/(r+g+b), g/(r+g+b) (diagonal Mahalanobis distance between the two samples' means, with their own
    spreads). 0 when either side has fewer than ``min_crossing_rays`` beams: no contrast can be seen.

    Paper 001 scores every beam's colour independently under one Gaussian per class, so a wall whose paint
    the two classes do not separate (or a wall of another paint, e.g. an end wall) gains a little per beam,
    enough summed over a door-wide run to pay for a door. A door that never moved is told apart from its wall
    by colour only when the colour changes where it begins and ends; that is what this measures.
    Chromaticity, not RGB: brightness along a wall changes with the lighting and a camera's exposure (both
    scale the three channels alike), the paint's hue does not (normalized rgb, Gevers & Smeulders 1999).
    """
    if inside.shape[0] < config.min_crossing_rays or beside.shape[0] < config.min_crossing_rays:
        return 0.0
    chroma = [c[:, :2] / np.maximum(c.sum(axis=1, keepdims=True), 1.0) for c in (inside, beside)]
    level = max(float(inside.sum(axis=1).mean()), float(beside.sum(axis=1).mean()), 1.0)
    pooled = np.maximum(0.5 * (chroma[0].var(axis=0) + chroma[1].var(axis=0)), config.color_var_floor / level**2)
    return float(np.sqrt(np.sum((chroma[0].mean(axis=0) - chroma[1].mean(axis=0)) ** 2 / pooled)))


def _near_existing(c: DoorCandidate, obj_map: ObjectMap, radius: float) -> bool:
    for i, d in enumerate(obj_map.doors):
        w = obj_map.door_width(i)
        ends = d.hinge + w * np.stack([np.cos(d.yaws), np.sin(d.yaws)], axis=1)
        mids = 0.5 * (d.hinge + ends)
        pts = np.concatenate([d.hinge[None], ends, mids])
        if float(np.min(np.linalg.norm(pts - c.hinge, axis=1))) < radius:
            return True
    return False


def _door_fit(beams: BeamSet, c: DoorCandidate, width: float, config: ObjectMapConfig) -> Door:
    """Initial angles by the pseudo-E-step search, then eq. (10) on the points near the leaf."""
    sigma = config.sigma_m
    yaws = initial_angles(beams, c.hinge, width, c.fallback_yaw, config)
    pts = beams.points
    near = beams.hit & (np.linalg.norm(pts - c.hinge, axis=1) <= width + 3.0 * sigma)
    idx = np.flatnonzero(near)
    yaw = yaws[beams.pass_index[idx]]
    rel = pts[idx] - c.hinge
    along = rel[:, 0] * np.cos(yaw) + rel[:, 1] * np.sin(yaw)
    across = -rel[:, 0] * np.sin(yaw) + rel[:, 1] * np.cos(yaw)
    on = (np.abs(across) < config.pseudo_e_sigmas * sigma) & (along > -sigma) & (along < width + sigma)
    hinge, yaws = fit_hinge_angles(c.hinge, yaws, pts[idx[on]], beams.pass_index[idx[on]],
                                   np.exp(-0.5 * (across[on] / sigma) ** 2), config.hinge_descent_iterations)
    return Door(hinge, yaws)


def _covered(segments: FloatArray, s: float) -> bool:
    return bool(np.any((segments[:, 0] <= s) & (segments[:, 1] >= s))) if segments.size else False


def _merge(intervals: FloatArray) -> FloatArray:
    """Union of intervals (K, 2), touching ones joined."""
    if intervals.shape[0] == 0:
        return intervals
    iv = intervals[np.argsort(intervals[:, 0])]
    out = [iv[0].copy()]
    for a, b in iv[1:]:
        if a <= out[-1][1] + 1e-9:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append(np.array([a, b]))
    return np.array(out)


def recut_window(beams: BeamSet, obj_map: ObjectMap, j: int, lo: float, hi: float, config: ObjectMapConfig
                 ) -> FloatArray:
    """Wall j's segments with the DP (eq. 9) re-run on the crossings within [lo, hi] only: outside, the
    segments stay; a segment that runs into the window edge is continued through it (an anchor point of
    overwhelming gain at the edge), so the splice stays one segment."""
    w = obj_map.walls[j]
    cross = line_crossings(beams, w.normal, w.offset, config.sigma_m)
    inside = (cross.s >= lo) & (cross.s <= hi)
    idx = cross.beam[inside]
    empty = FirstObjects.none(len(beams))
    local = _full_first(beams, obj_map, idx, empty)
    delta, kind = first_without(beams, local, idx, obj_map, WALL, j)
    gain = crossing_gains(beams, idx, cross.t[inside], delta, kind, WALL, obj_map.classes,
                          config.validity_prior, config.sigma_m)
    s_in = cross.s[inside]
    anchors = [edge for edge in (lo, hi) if _covered(w.segments, edge)]
    s_all = np.concatenate([s_in, anchors])
    g_all = np.concatenate([gain, np.full(len(anchors), 1e9)])
    segs, _ = segment_dp(s_all, g_all, config.rho_length_per_m, 2.0 * config.rho_static)
    outside = [np.array([a, min(b, lo)]) for a, b in w.segments if a < lo]
    outside += [np.array([max(a, hi), b]) for a, b in w.segments if b > hi]
    parts = np.array([*outside, *segs]) if (outside or segs.size) else np.zeros((0, 2))
    merged = _merge(parts.reshape(-1, 2))
    return merged[merged[:, 1] > merged[:, 0]] if merged.size else merged


def _recut_walls(beams: BeamSet, obj_map: ObjectMap, near: FloatArray, radius: float, config: ObjectMapConfig
                 ) -> tuple[ObjectMap, list[tuple[int, float, float]]]:
    """Re-cut (within a window about ``near``) the walls whose line passes within ``radius`` of it."""
    walls = list(obj_map.walls)
    changed: list[tuple[int, float, float]] = []
    for j, w in enumerate(obj_map.walls):
        if abs(float(near @ w.normal) - w.offset) > radius:
            continue
        s_near = float(near @ w.tangent)
        lo, hi = s_near - radius - config.recut_window_margin_m, s_near + radius + config.recut_window_margin_m
        segs = recut_window(beams, replace(obj_map, walls=walls), j, lo, hi, config)
        walls[j] = Wall(w.normal, w.offset, segs)
        changed.append((j, lo, hi))
    return replace(obj_map, walls=walls), changed


def _full_first(beams: BeamSet, obj_map: ObjectMap, idx: IntArray, template: FirstObjects) -> FirstObjects:
    """First objects of the beams ``idx`` under ``obj_map`` (the others left as in ``template``)."""
    delta, cls, obj = template.delta.copy(), template.cls.copy(), template.obj.copy()
    for t in range(beams.n_passes):
        sel = idx[beams.pass_index[idx] == t]
        segs, seg_cls, seg_obj = obj_map.segments(t)
        rng, hit = cast_segments(beams.origin[sel], beams.direction[sel], segs)
        delta[sel] = rng
        cls[sel] = -1
        obj[sel] = -1
        got = hit >= 0  # (none when the map has no segment in this pass)
        cls[sel[got]] = seg_cls[hit[got]]
        obj[sel[got]] = seg_obj[hit[got]]
    return FirstObjects(delta, cls, obj)


def _affected(beams: BeamSet, door: Door, width: float, changed: list[tuple[int, float, float]],
              obj_map: ObjectMap, sigma: float, margin_m: float) -> IntArray:
    """Beams whose likelihood may change: rays passing near the door, and rays crossing a re-cut wall in
    its window."""
    mask = rays_near(beams, door.hinge, width + margin_m)
    for j, lo, hi in changed:
        w = obj_map.walls[j]
        cross = line_crossings(beams, w.normal, w.offset, sigma)
        mask[cross.beam[(cross.s >= lo) & (cross.s <= hi)]] = True
    return np.flatnonzero(mask)


def _walls_behind(beams: BeamSet, obj_map: ObjectMap, idx: IntArray, first: FirstObjects, config: ObjectMapConfig
                  ) -> tuple[ObjectMap, IntArray]:
    """Walls seen only through a doorway, introduced with its door (the pseudo-E-step's point: before the
    door, the wall piece over the doorway occludes them). Hough lines of the affected rays' end points that
    the map leaves unexplained; each is kept when its DP (given the map with the door) pays for it.
    Returns the map and the beams whose first object may have changed."""
    sub = beams.subset(idx)
    far = sub.hit & (sub.range_m > first.delta[idx] + config.pseudo_e_sigmas * config.sigma_m) | (
        sub.hit & ~np.isfinite(first.delta[idx]))
    pts = sub.points[far]
    extra: list[IntArray] = []
    walls = list(obj_map.walls)
    for normal, offset, _ in hough_lines(pts, config.hough_step_deg, config.hough_offset_bin_m,
                                         config.hough_orientation_share, config.hough_min_points, 4):
        r = pts @ normal - offset
        sel = np.abs(r) < config.pseudo_e_sigmas * config.sigma_m + config.hough_offset_bin_m
        if int(sel.sum()) < config.hough_min_points:
            continue
        normal, offset = fit_line(pts[sel], np.exp(-0.5 * (r[sel] / config.sigma_m) ** 2) + 1e-12)
        current = replace(obj_map, walls=walls)
        cross = line_crossings(beams, normal, offset, config.sigma_m)
        empty = FirstObjects.none(len(beams))
        local = _full_first(beams, current, cross.beam, empty)
        segs, cost = wall_segments(beams, local, current, -1, normal, offset, config.validity_prior,
                                   config.sigma_m, config.rho_length_per_m, 2.0 * config.rho_static)
        if segs.shape[0] and cost + 2.0 * config.rho_static < 0.0:
            walls.append(Wall(normal, offset, segs))
            extra.append(cross.beam[(cross.s >= segs[0, 0] - 0.1) & (cross.s <= segs[-1, 1] + 0.1)])
    return replace(obj_map, walls=walls), (np.concatenate(extra) if extra else np.zeros(0, dtype=np.int64))


@dataclass(frozen=True)
class DoorTrial:
    """A door fitted at a candidate: the local log-posterior change of the map with it (``gain``), the
    margin by which it beats the better of no door and its leaf as a static segment (``margin``; Sec. VI
    adopts a door when this is positive), and the map with it."""

    gain: float
    margin: float
    obj_map: ObjectMap



def index_union(n: int, *parts: npt.ArrayLike) -> IntArray:
    """The sorted union of index arrays into range(n), as ``np.union1d`` gives it, through a mask: O(n), where
    union1d sorts or hashes (0.1 s a call at a million beams, a fifth of the final step on a long log)."""
    mask = np.zeros(n, dtype=np.bool_)
    for part in parts:
        mask[np.asarray(part, dtype=np.intp)] = True
    return np.flatnonzero(mask)

def with_fitted_door(beams: BeamSet, obj_map: ObjectMap, c: DoorCandidate, config: ObjectMapConfig
                     ) -> tuple[ObjectMap, IntArray]:
    """The map with a door fitted at candidate ``c`` (its nearby walls re-cut, the walls seen through its
    doorway added) and the beams whose likelihood that may change."""
    width = obj_map.classes.door_width_m
    door = _door_fit(beams, c, width, config)
    with_door = replace(obj_map, doors=[*obj_map.doors, door])
    new_map, changed = _recut_walls(beams, with_door, door.hinge, width + config.door_wall_margin_m, config)
    idx = _affected(beams, door, width, changed, new_map, config.sigma_m, config.door_ray_margin_m)
    first_mid = _full_first(beams, new_map, idx, FirstObjects.none(len(beams)))
    new_map, extra = _walls_behind(beams, new_map, idx, first_mid, config)
    return new_map, index_union(len(beams), idx, extra)


def try_door(beams: BeamSet, state: MapState, c: DoorCandidate, config: ObjectMapConfig) -> DoorTrial:
    """Fit a door at candidate ``c`` (:func:`with_fitted_door`) and score it."""
    obj_map = state.obj_map
    new_map, idx = with_fitted_door(beams, obj_map, c, config)
    before = float(state.loglik[idx].sum()) + log_prior(obj_map, config)
    gain = _local_log_posterior(beams, idx, new_map, config) - before
    # Sec. VI: the door is adopted only if it scores higher than the map without it, "i.e. when the segment
    # is static": the same leaf (first pass's direction) as a wall of its own
    gain_static = _local_log_posterior(beams, idx, as_static_segment(new_map, len(new_map.doors) - 1), config) - before
    return DoorTrial(gain, min(gain, gain - gain_static), new_map)


def _local_log_posterior(beams: BeamSet, idx: IntArray, obj_map: ObjectMap, config: ObjectMapConfig) -> float:
    """Σ over beams ``idx`` of the marginal log-likelihood under ``obj_map``, plus log p(M): the part of the
    log posterior that a change confined to those beams' rays can move."""
    sub = beams.subset(idx)
    first = _full_first(sub, obj_map, np.arange(idx.size), FirstObjects.none(idx.size))
    _, ll = e_step(sub, first, obj_map.classes, config.validity_prior, config.sigma_m)
    return float(ll.sum()) + log_prior(obj_map, config)


def terminate_doors(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> tuple[MapState, int]:
    """The other half of Sec. VI's outer loop ("new objects are introduced, and others are terminated"):
    each door, as EM left it, against the map without it and with its leaf as a static wall segment (the
    alternative the paper adopts a door against); the best of the three is kept. A door adopted early can
    stop paying once later doors and walls explain its rays."""
    terminated = 0
    for i in reversed(range(len(state.obj_map.doors))):
        obj_map = state.obj_map
        idx = np.flatnonzero(rays_near(beams, obj_map.doors[i].hinge,
                                       obj_map.door_width(i) + config.door_ray_margin_m))
        current = float(state.loglik[idx].sum()) + log_prior(obj_map, config)
        options = [replace(obj_map, doors=obj_map.doors[:i] + obj_map.doors[i + 1:]), as_static_segment(obj_map, i)]
        scores = [_local_log_posterior(beams, idx, m, config) for m in options]
        if max(scores) > current:
            state = evaluate(beams, options[int(np.argmax(scores))], config)
            terminated += 1
    return state, terminated


def as_static_segment(obj_map: ObjectMap, i: int) -> ObjectMap:
    """The map with door i replaced by a static wall segment where its leaf stands in the first pass."""
    door = obj_map.doors[i]
    yaw = float(door.yaws[0])
    tangent = np.array([np.cos(yaw), np.sin(yaw)])
    normal = np.array([tangent[1], -tangent[0]])  # so that (−n_y, n_x) = tangent
    s0 = float(door.hinge @ tangent)
    wall = Wall(normal, float(door.hinge @ normal), np.array([[s0, s0 + obj_map.door_width(i)]]))
    doors = obj_map.doors[:i] + obj_map.doors[i + 1:]
    return replace(obj_map, doors=doors, walls=[*obj_map.walls, wall])


def add_doors(beams: BeamSet, state: MapState, candidates: list[DoorCandidate], config: ObjectMapConfig
              ) -> tuple[MapState, int]:
    """Try the candidates, strongest first, in pairs (both ends of one piece). Of the two ends, the one whose
    map explains the data better (the larger ``gain``) is the door's hinge; it is kept when it beats both the
    map without it and its leaf as a static segment (``margin`` > 0). (The margin does not choose the end: a
    wrong end's static alternative, a segment across the doorway, is so poor that its margin is its whole
    gain, while the right end's leaf, static, already explains the pass it was taken from.)"""
    added = 0
    order = sorted(range(0, len(candidates), 2), key=lambda k: -candidates[k].support)
    kept: list[list[DoorCandidate]] = []
    for k in order:  # one pair per doorway: pairs whose ends coincide (within a cluster distance) are one
        pair = candidates[k: k + 2]
        if not any(min(float(np.linalg.norm(a.hinge - b.hinge)) for a in pair for b in other) < config.candidate_merge_m
                   for other in kept):
            kept.append(pair)
    for pair in kept[: config.max_door_candidates]:
        if any(_near_existing(c, state.obj_map, config.existing_door_radius_m) for c in pair):
            continue
        best = max((try_door(beams, state, c, config) for c in pair), key=lambda trial: trial.gain)
        if best.margin > 0.0:
            state = evaluate(beams, best.obj_map, config)
            added += 1
    return state, added


def recut_all_walls(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> MapState:
    """One sweep of eq. (9) over every wall in turn (lines kept), each given every other object: after each
    wall the first objects of the rays crossing its line are recast, so every DP sees the current map and
    the sweep never lowers the log posterior. Walls left without segments stay (empty) until the caller
    drops them, so object indices hold."""
    obj_map, first = state.obj_map, state.first
    walls = list(obj_map.walls)
    for j, wall in enumerate(walls):
        segs, _ = wall_segments(beams, first, replace(obj_map, walls=walls), j, wall.normal, wall.offset,
                                config.validity_prior, config.sigma_m, config.rho_length_per_m,
                                2.0 * config.rho_static)
        walls[j] = Wall(wall.normal, wall.offset, segs)
        changed = index_union(len(beams), np.flatnonzero((first.cls == WALL) & (first.obj == j)),
                              rays_meeting_line_before(beams, wall.normal, wall.offset, first.delta))
        first = _full_first(beams, replace(obj_map, walls=walls), changed, first)
    return evaluate(beams, replace(obj_map, walls=walls), config)


def _recut_sweeps(beams: BeamSet, state: MapState, config: ObjectMapConfig, trace: EmTrace | None = None
                  ) -> MapState:
    """Sweeps of eq. (9) over all walls while the log posterior rises (at most ``final_recut_sweeps``)."""
    for _ in range(config.final_recut_sweeps):
        new = recut_all_walls(beams, state, config)
        if trace is not None:
            trace.step()
        if new.log_posterior <= state.log_posterior:
            break
        state = new
    return state


def reacquire_occluded(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> ObjectMap:
    """Every wall gains the segments eq. (9) finds on its line when the rays are allowed to see through
    the objects they passed through (paper 001 Sec. VI's pseudo-E-step; ``wall_segments(see_through_band_m)``,
    the band the pseudo-E-step's: pseudo_e_sigmas·σ), its own segments kept.

    Why: a wall drawn across a doorway and a room wall behind it are a local optimum of the per-wall DP. The
    rays through the doorway end on nothing mapped, so they cost the bridge nothing (Δ ≈ 0; a gap of width w
    is bridged whenever ρL·w < 2ρS, w < 1 m); and the room wall's hits behind the bridge are occluded, so no
    segment of it pays. Re-acquiring the hidden segments lets the next sweep see both at once."""
    obj_map = state.obj_map
    band = config.pseudo_e_sigmas * config.sigma_m
    same: list[Wall] = []
    grown: list[Wall] = []
    for j, wall in enumerate(obj_map.walls):
        segs, _ = wall_segments(beams, state.first, obj_map, j, wall.normal, wall.offset, config.validity_prior,
                                config.sigma_m, config.rho_length_per_m, 2.0 * config.rho_static,
                                see_through_band_m=band)
        merged = _merge(np.concatenate([wall.segments.reshape(-1, 2), segs]))
        unchanged = merged.shape == wall.segments.shape and np.allclose(merged, wall.segments)
        (same if unchanged else grown).append(Wall(wall.normal, wall.offset, merged))
    # grown walls last: the sweep re-cuts their occluders first, while it can still see what lies behind them
    return replace(obj_map, walls=same + grown)


def final_walls(beams: BeamSet, obj_map: ObjectMap, config: ObjectMapConfig, trace: EmTrace | None = None
                ) -> ObjectMap:
    """Walls once more over the final step's beams (by default every scan and beam of the log), once the
    structure has converged: Hough proposals that now pay for themselves (propose_walls), then sweeps of
    eq. (9) over all walls while the log posterior rises (at most ``final_recut_sweeps``); then the
    occluded segments re-acquired (reacquire_occluded) and swept again, kept only if the log posterior
    (occlusion modelled) ends higher; walls left without segments are dropped.

    Why: the search runs on every scan_stride-th scan and beam_stride-th beam, so a segment's evidence Σ Δ
    is ~stride² smaller than the log's against the paper's ρL, ρS (set for the paper's full data): sparse
    tails and short walls (e.g. a room's side wall seen through a doorway) were cut.
    """
    state = _recut_sweeps(beams, evaluate(beams, propose_walls(beams, obj_map, config), config), config, trace)
    best, best_log_posterior = state.obj_map, state.log_posterior
    if config.final_recut_sweeps:
        grown = reacquire_occluded(beams, state, config)
        del state  # its per-beam arrays are not needed while the trial runs (long logs: hundreds of MB)
        trial = _recut_sweeps(beams, evaluate(beams, grown, config), config, trace)
        if trial.log_posterior > best_log_posterior:
            best = trial.obj_map
    return replace(best, walls=[w for w in best.walls if w.segments.shape[0]])


def search_structure(beams: BeamSet, config: ObjectMapConfig, classes: ClassParams | None = None,
                     trace: EmTrace | None = None, seeds: Sequence[DoorCandidate] = ()) -> MapState:
    """The whole stage: walls, EM, then rounds of door proposals and EM. ``classes`` given: they are
    applied as they are (not relearned), as in paper 001 Fig. 5b. ``seeds``: doors found by motion elsewhere
    (the grid stage's), fitted into the map before the first round whatever they score, so that the door
    class (width, colours) learns from them from the start (Sec. VI: the colour model improves as doors are
    found "based on motion, for example"); the rounds' termination then drops those that do not pay (what
    they taught the classes stays, and the walls re-cut around them are re-cut by the later sweeps)."""
    learn = classes is None
    cls0 = classes if classes is not None else initial_classes(beams, config)
    if cls0.has_color and not (config.use_color and beams.has_color):
        cls0 = replace(cls0, has_color=False)
    obj_map = ObjectMap([], [], cls0, beams.n_passes)
    obj_map = propose_walls(beams, obj_map, config)
    state = run_em(beams, obj_map, config, learn, trace=trace)
    fitted = 0
    for c in seeds:
        if not _near_existing(c, state.obj_map, config.existing_door_radius_m):
            state = evaluate(beams, with_fitted_door(beams, state.obj_map, c, config)[0], config)
            fitted += 1
    if fitted:  # EM with them, then each faces termination as an adopted door does
        state = run_em(beams, state.obj_map, config, learn, trace=trace)
        state, _ = terminate_doors(beams, state, config)
    for _ in range(config.structure_rounds):
        candidates = motion_candidates(beams, state, config)
        if state.obj_map.doors or not learn:
            candidates += color_candidates(beams, state, config)
        state, added = add_doors(beams, state, candidates, config)
        if not added:
            break
        state = run_em(beams, state.obj_map, config, learn, trace=trace)
        state, _ = terminate_doors(beams, state, config)
    return state
