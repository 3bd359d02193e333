"""The em stage of ``doorbatch map``: recordings and their pass poses → beams → object map → outputs.

    beams  = every scan_stride-th scan, beam_stride-th beam of every pass, in the map frame (+ colours)
    state  = structure search with EM (search.py), or with given class parameters (paper 001 Fig. 5b)
    doors  = hinge, width, closed direction (the wall line through the hinge), opening range, moved
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, ObjectMapConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.segments import point_segment_distance
from doorbatch.io.preview import PreviewDoor
from doorbatch.io.recording import Recording
from doorbatch.pipeline.gridmap.doors import DetectedDoor
from doorbatch.pipeline.mapping import PassPoses
from doorbatch.pipeline.objectmap.beams import BeamSet, ScanBeams, beams_from_scans
from doorbatch.pipeline.objectmap.em import EmTrace, MapState, evaluate
from doorbatch.pipeline.objectmap.model import DOOR, WALL, ClassParams, ObjectMap, Wall
from doorbatch.pipeline.objectmap.search import (
    DoorCandidate,
    as_static_segment,
    color_contrast,
    final_walls,
    search_structure,
)
from doorbatch.progress import progress_bar

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def pass_scans(rec: Recording, poses: PassPoses, scan_stride: int, config: ObjectMapConfig) -> list[ScanBeams]:
    """The scans of one pass that have a pose, every ``scan_stride``-th, less those of a robot standing still.

    A scan within ``still_travel_m`` and ``still_turn_deg`` of the last one kept, and less than ``still_interval_s``
    after it, is left out (Cartographer's motion filter; GMapping's linearUpdate / angularUpdate / temporalUpdate):
    a standing robot repeats one view, and each copy would weigh that view once more against the priors ρ of
    paper 001 (and cost its time and memory)."""
    sc = rec.scans
    out = []
    last: int | None = None
    interval_ns = config.still_interval_s * 1e9
    for i in range(0, len(sc), scan_stride):
        if not poses.valid[i]:
            continue
        if last is not None:
            step = poses.poses[i] - poses.poses[last]
            if (math.hypot(step[0], step[1]) < config.still_travel_m
                    and abs(float(wrap_angle(step[2]))) < math.radians(config.still_turn_deg)
                    and sc.stamps_ns[i] - sc.stamps_ns[last] < interval_ns):
                continue
        last = i
        n = sc.ranges[i].shape[0]
        colors = None
        if config.use_color and rec.colors is not None and rec.colors[i].shape[0] == n:
            colors = rec.colors[i].astype(np.float64)
            if rec.color_valid is not None:
                colors[~rec.color_valid[i]] = np.nan
        angles = sc.angle_min[i] + sc.angle_increment[i] * np.arange(n)
        out.append(ScanBeams(poses.poses[i], sc.laser_to_base[i], angles, sc.ranges[i].astype(np.float64),
                             float(sc.range_min[i]), float(sc.range_max[i]), colors))
    return out


def _split(k: int, scan_stride: int, beam_stride: int) -> tuple[int, int]:
    """(scan stride, beam stride) that keep 1 beam in about k: the configured ones where set (> 0), the
    others derived, beam stride = ⌊√k⌋ and scan stride = ⌊k / beam stride⌋ (one set: the other ⌊k / it⌋)."""
    if not beam_stride:
        beam_stride = max(1, k // scan_stride) if scan_stride else max(1, math.isqrt(k))
    if not scan_stride:
        scan_stride = max(1, k // beam_stride)
    return int(scan_stride), int(beam_stride)


def strides_for_rate(beams_per_s: float, config: ObjectMapConfig) -> tuple[int, int]:
    """The search's (scan stride, beam stride) for a log of ``beams_per_s``: ``config.scan_stride`` and
    ``beam_stride`` where set (> 0), the others derived so that at least ``kept_beams_per_s`` are kept,

        k = min(⌊beams_per_s / kept_beams_per_s⌋, max(max_thinning, ⌊beams_per_s / dense_kept_beams_per_s⌋)),

    at least 1, split by :func:`_split`: a sparse laser is not thinned at all, an ordinary one by at most
    max_thinning, a denser one down to dense_kept_beams_per_s."""
    if not np.isfinite(beams_per_s):
        return _split(1, config.scan_stride, config.beam_stride)
    cap = max(config.max_thinning, int(beams_per_s // config.dense_kept_beams_per_s))
    k = max(1, min(int(beams_per_s // config.kept_beams_per_s), cap))
    return _split(k, config.scan_stride, config.beam_stride)


def final_strides_for_rate(beams_per_s: float, config: ObjectMapConfig) -> tuple[int, int]:
    """The final wall step's (scan stride, beam stride): ``final_scan_stride`` and ``final_beam_stride`` where
    set (> 0), the others derived from k = max(1, ⌊beams_per_s / final_kept_beams_per_s⌋) by :func:`_split`:
    every beam of every laser up to that rate, a denser one thinned to it."""
    k = max(1, int(beams_per_s // config.final_kept_beams_per_s)) if np.isfinite(beams_per_s) else 1
    return _split(k, config.final_scan_stride, config.final_beam_stride)


def beams_per_second(recordings: Sequence[Recording]) -> float:
    """The logs' data rate: the median beams per scan over the median interval between scans (0 where the logs
    give no rate)."""
    intervals = [np.diff(r.scans.stamps_ns) * 1e-9 for r in recordings if len(r.scans) > 1]
    dt = np.concatenate(intervals) if intervals else np.zeros(0)
    dt = dt[dt > 0.0]
    counts = [len(x) for r in recordings for x in r.scans.ranges]
    return float(np.median(counts)) / float(np.median(dt)) if dt.size and counts else 0.0


def em_strides(recordings: Sequence[Recording], config: ObjectMapConfig) -> tuple[int, int]:
    """:func:`strides_for_rate` at the logs' data rate (:func:`beams_per_second`; 1, 1 where the logs give no
    rate); the configured strides where both are set."""
    if config.scan_stride and config.beam_stride:
        return config.scan_stride, config.beam_stride
    return strides_for_rate(beams_per_second(recordings), config)


def with_strides(recordings: Sequence[Recording], config: ObjectMapConfig) -> ObjectMapConfig:
    """``config`` with the search's and the final wall step's strides resolved for these logs
    (:func:`em_strides`, :func:`final_strides_for_rate`)."""
    searched = config.scan_stride and config.beam_stride
    final = config.final_scan_stride and config.final_beam_stride
    rate = 0.0 if searched and final else beams_per_second(recordings)
    scan_stride, beam_stride = (config.scan_stride, config.beam_stride) if searched else strides_for_rate(rate, config)
    final_scan, final_beam = ((config.final_scan_stride, config.final_beam_stride) if final
                              else final_strides_for_rate(rate, config))
    return config.model_copy(update={"scan_stride": scan_stride, "beam_stride": beam_stride,
                                     "final_scan_stride": final_scan, "final_beam_stride": final_beam})


def collect_beams(recordings: Sequence[Recording], passes: Sequence[PassPoses], config: ObjectMapConfig,
                  strides: tuple[int, int] | None = None) -> BeamSet:
    """All passes' kept beams in the map frame: every n-th scan and beam by ``strides`` (scan, beam), by
    default the search's (:func:`em_strides`); (1, 1): every beam of every scan but a standing robot's repeats
    (:func:`pass_scans`)."""
    scan_stride, beam_stride = strides or em_strides(recordings, config)
    scans = [pass_scans(r, p, scan_stride, config) for r, p in zip(recordings, passes, strict=True)]
    return beams_from_scans(scans, config.max_range_m, beam_stride)


@dataclass(frozen=True)
class FinalStepBeams:
    """The final wall step's beams, and 1 in how many of its scans they keep (:func:`final_step_beams`)."""

    beams: BeamSet
    scan_thinning: int  # 1: every scan (after final_scan_stride and the standing robot's repeats)
    scans: int  # the scans before thinning
    beams_before: int  # their beams (after final_beam_stride)


def final_step_beams(recordings: Sequence[Recording], passes: Sequence[PassPoses], config: ObjectMapConfig
                     ) -> FinalStepBeams | None:
    """The beams of the final wall step (final_scan_stride, final_beam_stride); where more than
    ``final_max_beams`` would be kept, 1 scan in k of each pass, k the smallest for which they fit. None when the
    step is off."""
    if not config.final_recut_sweeps:
        return None
    if not (config.final_scan_stride and config.final_beam_stride):  # em_stage has resolved them already
        config = with_strides(recordings, config)
    scans = [pass_scans(r, p, config.final_scan_stride, config) for r, p in zip(recordings, passes, strict=True)]

    def count(thin: int) -> int:
        return sum(-(-sc.ranges.shape[0] // config.final_beam_stride) for one in scans for sc in one[::thin])

    total = count(1)
    budget = config.final_max_beams
    thin = 1
    if budget and total > budget:
        thin = -(-total // budget)  # a lower bound: passes keep ceil(n / k) scans, and scans differ in size
        while count(thin) > budget and thin < max(map(len, scans)):
            thin += 1
    kept = scans if thin == 1 else [one[::thin] for one in scans]
    return FinalStepBeams(beams_from_scans(kept, config.max_range_m, config.final_beam_stride), thin,
                          sum(map(len, scans)), total)


@dataclass(frozen=True)
class EmDoor:
    """A door of the object map as doors.parquet describes it, with its per-pass angles."""

    preview: PreviewDoor
    n_observations: int
    pass_yaws: FloatArray
    pass_observed: npt.NDArray[np.bool_]


@dataclass(frozen=True)
class ObjectMapResult:
    """What the em stage returns."""

    object_map: ObjectMap
    doors: list[EmDoor]
    log_posterior: float
    n_beams: int
    trace: EmTrace
    seconds: float
    strides: tuple[int, int]  # the search's (scan, beam) strides; 0: not resolved (beams given directly)
    final_beams: int = 0  # beams of the final wall step (0: none)
    final_scan_thinning: int = 1  # its 1 scan in k (em.final_max_beams)
    final_strides: tuple[int, int] = (1, 1)  # its (scan, beam) strides (em.final_kept_beams_per_s)


def _covered_fraction(wall: Wall, s0: float, s1: float) -> float:
    """The fraction of the interval [s0, s1] along the wall's line that its segments cover."""
    if not wall.segments.size or s1 <= s0:
        return 0.0
    overlap = np.clip(np.minimum(wall.segments[:, 1], s1) - np.maximum(wall.segments[:, 0], s0), 0.0, None)
    return float(overlap.sum() / (s1 - s0))


def _tangent_yaw(wall: Wall) -> float:
    return float(np.arctan2(wall.tangent[1], wall.tangent[0]))


def closed_yaw(obj_map: ObjectMap, i: int, max_distance_m: float, observed: BoolArray | None = None,
               min_turn_rad: float = 0.0) -> float:
    """The closed direction of door i: along a wall line through its hinge, towards the doorway.

    A closed leaf lies across the gap a wall line's segments leave (the leaf's span, less a tenth of the width at
    each end, less than half covered). For a door seen at angles at least ``min_turn_rad`` apart, the line is the
    nearest within ``max_distance_m`` of the hinge that has such a gap on exactly one side of it, the wall going
    on along the other and again beyond the gap (within half a width past it: the far jamb); a door jamb or a stub
    at the hinge, short on both sides, is no such line however near, nor is a wall that ends at a corner. With
    that line, the gap's side. A door seen at one angle is judged on the nearest line alone: a niche's side wall
    taken for a leaf standing open then lies along that line, closed, and the colour test can return it to the
    wall (double_door:5). Otherwise, along the nearest line, the direction closest to the leaf's directions in the
    passes it was seen in (``observed``; all passes when none): a door that never moved stands at one angle that
    is as far from either side, and an unseen pass's direction is only the search's guess. Without a wall line
    near the hinge: the first observed pass's direction.
    """
    door = obj_map.doors[i]
    yaws = door.yaws[observed] if observed is not None and observed.any() else door.yaws
    width = obj_map.door_width(i)
    near = sorted((abs(float(door.hinge @ w.normal) - w.offset), k) for k, w in enumerate(obj_map.walls))
    near = [(d, k) for d, k in near if d <= max_distance_m]
    if not near:
        return float(yaws[0])
    around = np.sort(np.mod(yaws, 2 * np.pi))
    moved = 2 * np.pi - float(np.diff(np.append(around, around[0] + 2 * np.pi)).max()) >= min_turn_rad  # the arc
    for _, k in near if moved else near[:1]:
        wall = obj_map.walls[k]
        s_hinge = float(door.hinge @ wall.tangent)
        gap = np.array([_covered_fraction(wall, s_hinge + 0.1 * width, s_hinge + 0.9 * width) < 0.5,
                        _covered_fraction(wall, s_hinge - 0.9 * width, s_hinge - 0.1 * width) < 0.5])
        jamb = np.array([_covered_fraction(wall, s_hinge + width, s_hinge + 1.5 * width) > 0.0,
                         _covered_fraction(wall, s_hinge - 1.5 * width, s_hinge - width) > 0.0])
        if gap.sum() == 1 and jamb[np.argmax(gap)]:  # a doorway: the door closes into it, whatever its angles
            return float(wrap_angle(_tangent_yaw(wall) + (0.0 if gap[0] else np.pi)))
    base = _tangent_yaw(obj_map.walls[near[0][1]])
    options = np.array([base, base + np.pi])
    cost = [np.min(np.abs(wrap_angle(yaws - o))) for o in options]
    return float(wrap_angle(options[int(np.argmin(cost))]))


def wall_distance(obj_map: ObjectMap, point: FloatArray) -> float:
    """Distance from ``point`` to the nearest wall segment of the map (inf without walls)."""
    segments = [w.endpoints() for w in obj_map.walls if w.segments.size]
    return float(point_segment_distance(point, np.concatenate(segments)).min()) if segments else float("inf")


def _door_angles(obj_map: ObjectMap, i: int, observed: BoolArray, config: ObjectMapConfig
                 ) -> tuple[float, FloatArray, BoolArray]:
    """Door i's closed direction, its angles relative to it, and the passes that show the leaf: ``observed``
    less those whose leaf is turned beyond max_opening_deg from closed (no door turns there, and what it
    explains is the wall behind the hinge: a leaf the fit left along it)."""
    yaws = obj_map.doors[i].yaws
    turn = math.radians(config.min_opening_deg)
    closed = closed_yaw(obj_map, i, config.wall_hinge_distance_m, observed, turn)
    rel = wrap_angle(yaws - closed)
    turnable = np.abs(rel) <= np.deg2rad(config.max_opening_deg)
    if np.any(observed & ~turnable):
        observed = observed & turnable
        closed = closed_yaw(obj_map, i, config.wall_hinge_distance_m, observed, turn)
        rel = wrap_angle(yaws - closed)
    return closed, rel, observed


def _moved(rel: FloatArray, observed: BoolArray, config: ObjectMapConfig) -> tuple[float, float, bool]:
    seen = rel[observed] if observed.any() else rel
    lo, hi = float(np.min(seen)), float(np.max(seen))
    return lo, hi, bool(observed.sum() >= 2 and hi - lo >= np.deg2rad(config.min_opening_deg))


def describe_doors(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> list[EmDoor]:
    """Doors as rows: angles relative to the closed direction over the passes the leaf was seen in.

    A door that never moved shows no hinge: both ends of its leaf explain the same hits. Where its free end
    lies on a wall (within ``wall_hinge_distance_m`` of a segment) and its hinge end off every wall, or
    farther from them than the free end by more than ``sigma_m`` (a leaf left open almost flat against a
    wall meets it at the hinge; its free end stands off it by length·sin(angle)), the ends are swapped: a
    hinge is mounted in a wall or frame (a door left open into a corridor while mapping).
    """
    out = []
    for i, door in enumerate(state.obj_map.doors):
        obj_map = state.obj_map
        mine = (state.first.cls == DOOR) & (state.first.obj == i) & beams.hit & (state.e > 0.5)
        # a pass shows the leaf's angle only by points off the hinge: those within the pseudo-E-step band
        # (pseudo_e_sigmas·σ) of it fit every angle (a hinge seen edge-on, the leaf hidden)
        off_hinge = np.linalg.norm(beams.points - door.hinge, axis=1) > config.pseudo_e_sigmas * config.sigma_m
        counts = np.bincount(beams.pass_index[mine & off_hinge], minlength=obj_map.n_passes)
        closed, rel, observed = _door_angles(obj_map, i, counts >= config.min_leaf_support, config)
        lo, hi, moved = _moved(rel, observed, config)
        if not moved:
            yaw = float(np.angle(np.mean(np.exp(1j * door.yaws[observed if observed.any() else slice(None)]))))
            tip = door.hinge + obj_map.door_width(i) * np.array([np.cos(yaw), np.sin(yaw)])
            near = config.wall_hinge_distance_m
            to_hinge, to_tip = wall_distance(obj_map, door.hinge), wall_distance(obj_map, tip)
            if to_tip <= near and (to_hinge > near or to_hinge - to_tip > config.sigma_m):
                door = replace(door, hinge=tip, yaws=np.full_like(door.yaws, wrap_angle(yaw + np.pi)))
                obj_map = replace(obj_map, doors=[*obj_map.doors[:i], door, *obj_map.doors[i + 1:]])
                closed, rel, observed = _door_angles(obj_map, i, observed, config)
                lo, hi, moved = _moved(rel, observed, config)
        out.append(EmDoor(PreviewDoor(float(door.hinge[0]), float(door.hinge[1]), obj_map.door_width(i), closed,
                                      lo, hi, moved), int(mine.sum()), door.yaws.copy(), observed))
    return out


def leaf_wall_contrast(beams: BeamSet, state: MapState, i: int, door: PreviewDoor, config: ObjectMapConfig) -> float:
    """The colour contrast (:func:`~doorbatch.pipeline.objectmap.search.color_contrast`) of door i's leaf
    against the wall it is hung in: the leaf's beams (first object door i, valid) against the hits on walls
    collinear with the closed direction's line through the hinge (within ``collinear_angle_deg`` of it and the
    pseudo-E-step band, from a door width behind the hinge to two ahead: the wall on both sides of the
    doorway; a wall across the line, as at a corner, is not the wall the door is in). 0 when either has too
    few beams. Where half a door width of wall is seen on both sides of the doorway, the lower of the two sides'
    contrasts: a door's colour changes where it begins and where it ends, and a door-wide piece at the end of a
    wall painted another colour (an accent wall) contrasts with the wall on one side only."""
    hinge = np.array([door.hinge_x, door.hinge_y])
    tangent = np.array([math.cos(door.closed_yaw), math.sin(door.closed_yaw)])
    first, width = state.first, door.length
    band = config.pseudo_e_sigmas * config.sigma_m
    rel = beams.points - hinge
    along, across = rel @ tangent, rel @ np.array([-tangent[1], tangent[0]])
    ok = beams.hit & np.isfinite(beams.color[:, 0])
    leaf = ok & (first.cls == DOOR) & (first.obj == i) & (state.e > 0.5)
    beside = (ok & (first.cls == WALL) & (np.abs(beams.range_m - first.delta) < band) & (np.abs(across) < band)
              & (along >= -width) & (along <= 2.0 * width))
    idx = np.flatnonzero(beside)
    if idx.size:
        normals = np.array([w.normal for w in state.obj_map.walls])[first.obj[idx]]
        beside[idx[np.abs(normals @ tangent) >= math.sin(math.radians(config.collinear_angle_deg))]] = False
    sides = [beside & (along < 0.0), beside & (along > width)]  # behind the hinge; beyond the free end

    def wall_seen(side: npt.NDArray[np.bool_]) -> bool:  # half a door width of wall at least: a casing is not one
        return int(side.sum()) >= config.min_crossing_rays and float(np.ptp(along[side])) >= 0.5 * width

    if all(wall_seen(side) for side in sides):
        return min(color_contrast(beams.color[leaf], beams.color[side], config) for side in sides)
    return color_contrast(beams.color[leaf], beams.color[beside], config)


def leaf_scatter(beams: BeamSet, state: MapState, i: int) -> float:
    """RMS distance of door i's hits (first object door i, e > 0.5, on the leaf's span [0, width]) from its
    leaf line in their pass; 0 without such hits."""
    door, width = state.obj_map.doors[i], state.obj_map.door_width(i)
    mine = np.flatnonzero((state.first.cls == DOOR) & (state.first.obj == i) & beams.hit & (state.e > 0.5))
    yaw = door.yaws[beams.pass_index[mine]]
    rel = beams.points[mine] - door.hinge
    along = rel[:, 0] * np.cos(yaw) + rel[:, 1] * np.sin(yaw)
    across = -rel[:, 0] * np.sin(yaw) + rel[:, 1] * np.cos(yaw)
    on = (along >= 0.0) & (along <= width)
    return float(np.sqrt(np.mean(across[on] ** 2))) if on.any() else 0.0


def wall_scatter(beams: BeamSet, state: MapState) -> float:
    """RMS distance of the walls' hits (first object a wall, e > 0.5) from their wall lines: the scatter this
    laser and these poses give a plane; NaN without such hits."""
    walls = state.obj_map.walls
    mine = np.flatnonzero((state.first.cls == WALL) & beams.hit & (state.e > 0.5))
    if not walls or not mine.size:
        return math.nan
    normals = np.array([w.normal for w in walls])[state.first.obj[mine]]
    offsets = np.array([w.offset for w in walls])[state.first.obj[mine]]
    across = np.einsum("ij,ij->i", beams.points[mine], normals) - offsets
    return float(np.sqrt(np.mean(across**2)))


def without_thick_leaves(beams: BeamSet, state: MapState, doors: list[EmDoor], config: ObjectMapConfig
                         ) -> tuple[MapState, list[EmDoor]]:
    """Doors whose hits scatter about their leaf's line (RMS, :func:`leaf_scatter`) by more than
    ``leaf_scatter_max_ratio`` times the walls' (:func:`wall_scatter`; the config's σ where there are no walls)
    are no doors: they are dropped from the map.

    Why: a leaf is a thin plane, so the same laser scatters its hits about its line as it scatters a wall's. The
    two faces a pillar or box shows from one side (an L) are not one line, but a leaf laid along the L's chord
    explains both within the pseudo-E band (3σ), and per-pass angles follow the faces each direction of travel
    shows (a "moved" door) or stay put (one "standing open"): hospital_long's 0.3–0.4 m pillars, hits 7.3 cm RMS
    off the chord against ≤ 1.1 cm for every true leaf. Measured against the walls, not the config's σ, a σ set
    at or below the laser's real noise drops no real leaf (a reviewer's sample with em.sigma_m 0.007)."""
    walls = wall_scatter(beams, state)  # floored at a laser's range resolution, 1 mm (a noise-free simulator)
    limit = config.leaf_scatter_max_ratio * (max(walls, 1e-3) if math.isfinite(walls) else config.sigma_m)
    thick = [i for i in range(len(doors)) if leaf_scatter(beams, state, i) > limit]
    if not thick:
        return state, doors
    obj_map = state.obj_map
    obj_map = replace(obj_map, doors=[d for i, d in enumerate(obj_map.doors) if i not in thick])
    state = evaluate(beams, obj_map, config)
    return state, describe_doors(beams, state, config)


def without_plain_still_doors(beams: BeamSet, state: MapState, doors: list[EmDoor], config: ObjectMapConfig
                              ) -> tuple[MapState, list[EmDoor]]:
    """Doors that never moved from their closed angle (within ``min_opening_deg`` of it in every pass that
    shows them) and whose leaf's colour does not stand out from the wall they are hung in
    (:func:`leaf_wall_contrast` below ``color_contrast_min_sigmas``) become static wall segments.

    Why: nothing but its colour tells a closed door that never moved from a piece of wall (paper 001 Sec. VI);
    a door class that explains wall paint (a component of the door colours fitted to white doors) lets a
    door-sized wall piece, e.g. beside a niche, pay for a door. The colour proposals test the same contrast;
    this holds every such door to it, whatever proposed it. A leaf that stood open at an angle all along is
    left to the shape evidence that found it (a door-sized piece standing out of a wall). Logs without colour
    are left alone (range-only EM's own limit)."""
    if not state.obj_map.classes.has_color or not beams.has_color:
        return state, doors
    closed = math.radians(config.min_opening_deg)
    plain = [i for i, d in enumerate(doors) if not d.preview.moved
             and max(abs(d.preview.angle_min), abs(d.preview.angle_max)) < closed
             and leaf_wall_contrast(beams, state, i, d.preview, config) < config.color_contrast_min_sigmas]
    if not plain:
        return state, doors
    obj_map = state.obj_map
    for i in reversed(plain):
        obj_map = as_static_segment(obj_map, i)
    state = evaluate(beams, obj_map, config)
    return state, describe_doors(beams, state, config)


def stride_weighted(config: ObjectMapConfig) -> ObjectMapConfig:
    """The prior's constants divided by scan_stride·beam_stride: the same balance as multiplying the data
    term by it (each kept beam stands for that many beams of the log). Strides as :func:`with_strides`
    resolves them."""
    if not (config.scan_stride and config.beam_stride):
        raise ValueError("stride_weighted needs resolved strides (with_strides)")
    k = float(config.scan_stride * config.beam_stride)
    return config.model_copy(update={"rho_global": config.rho_global / k, "rho_static": config.rho_static / k,
                                     "rho_dynamic": config.rho_dynamic / k,
                                     "rho_length_per_m": config.rho_length_per_m / k})


def build_object_map(beams: BeamSet, config: ObjectMapConfig, classes: ClassParams | None = None,
                     final: FinalStepBeams | None = None, seeds: Sequence[DoorCandidate] = (),
                     progress: Callable[[int], object] | None = None) -> ObjectMapResult:
    """The em stage on beams (see :func:`collect_beams`); ``classes`` given: applied without relearning.
    ``final`` (:func:`final_step_beams`) given and ``config.final_recut_sweeps`` > 0: the converged
    walls are proposed and re-cut once more over them (:func:`final_walls`). ``seeds``: doors found by motion
    (:func:`~doorbatch.pipeline.objectmap.search.search_structure`). ``progress``: called with 1 after every EM
    iteration and final sweep."""
    t0 = time.perf_counter()
    trace = EmTrace(on_step=progress)
    if config.stride_weighted_prior:
        config = stride_weighted(config)
    state = search_structure(beams, config, classes, trace, seeds)
    final = final if config.final_recut_sweeps > 0 else None
    if final is not None:
        state = evaluate(beams, final_walls(final.beams, state.obj_map, config, trace), config)
    state, doors = without_thick_leaves(beams, state, describe_doors(beams, state, config), config)
    state, doors = without_plain_still_doors(beams, state, doors, config)
    return ObjectMapResult(state.obj_map, doors, state.log_posterior, len(beams), trace, time.perf_counter() - t0,
                           (config.scan_stride, config.beam_stride), 0 if final is None else len(final.beams),
                           1 if final is None else final.scan_thinning,
                           (max(config.final_scan_stride, 1), max(config.final_beam_stride, 1)))


def em_stage(recordings: Sequence[Recording], passes: Sequence[PassPoses], config: DoorbatchConfig,
             classes: ClassParams | None = None, grid_doors: Sequence[DetectedDoor] = ()) -> ObjectMapResult:
    """The em stage of ``doorbatch map`` on loaded recordings and their poses (strides resolved for them:
    :func:`with_strides`); with ``em.seed_grid_doors``, the grid stage's doors seed the search."""
    em = with_strides(recordings, config.em)
    seeds = [DoorCandidate(np.array([d.hinge_x, d.hinge_y]), d.closed_yaw, "grid", d.n_observations)
             for d in grid_doors] if config.em.seed_grid_doors else []
    beams = collect_beams(recordings, passes, em)
    final = final_step_beams(recordings, passes, em)
    log.info("em stage: %d beams (every %d. scan, %d. beam), %d in the final wall step", len(beams), em.scan_stride,
             em.beam_stride, 0 if final is None else len(final.beams))
    with progress_bar(None, "map: em stage (--stages grid skips it)", unit="step") as bar:
        return build_object_map(beams, em, classes, final, seeds, progress=bar.update)
