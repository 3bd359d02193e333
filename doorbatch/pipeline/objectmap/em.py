"""EM for a fixed map structure (paper 001 Sec. V): E-step expectations, then the M-step sub-steps
(wall lines, wall segments, door hinges and angles, the global width, class colours) in turn."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from doorbatch.config import ObjectMapConfig
from doorbatch.pipeline.objectmap.beams import BeamSet
from doorbatch.pipeline.objectmap.colors import ml_class_colors
from doorbatch.pipeline.objectmap.doors import best_width, fit_hinge_angles, width_gains
from doorbatch.pipeline.objectmap.model import DOOR, WALL, Door, ObjectMap, Wall
from doorbatch.pipeline.objectmap.prior import log_prior
from doorbatch.pipeline.objectmap.sensor import FirstObjects, e_step, first_objects
from doorbatch.pipeline.objectmap.walls import fit_line, wall_segments

FloatArray = npt.NDArray[np.float64]


@dataclass
class MapState:
    """A map with its E-step: first objects, expectations e, per-beam log-likelihoods, log posterior."""

    obj_map: ObjectMap
    first: FirstObjects
    e: FloatArray
    loglik: FloatArray
    log_posterior: float


def evaluate(beams: BeamSet, obj_map: ObjectMap, config: ObjectMapConfig) -> MapState:
    """The E-step (eq. 7) and the log posterior log p(D | M) + log p(M) (eqs. 5, 6; validity summed out)."""
    first = first_objects(beams, obj_map)
    e, ll = e_step(beams, first, obj_map.classes, config.validity_prior, config.sigma_m)
    return MapState(obj_map, first, e, ll, float(ll.sum()) + log_prior(obj_map, config))


def merge_collinear(walls: list[Wall], max_angle_deg: float, max_offset_m: float) -> list[Wall]:
    """Walls whose lines coincide (within the angle and offset) become one wall with the union of their
    segments on the first one's line: a wall is the set of collinear segments (Sec. II)."""
    out: list[Wall] = []
    cos_max = np.cos(np.deg2rad(max_angle_deg))
    for w in walls:
        for k, o in enumerate(out):
            c = float(w.normal @ o.normal)
            if abs(c) >= cos_max and abs(w.offset * np.sign(c) - o.offset) <= max_offset_m:
                base = w.offset * w.normal
                ends = (base + w.segments[:, :, None] * w.tangent) @ o.tangent  # (K, 2) along o
                segs = np.sort(ends, axis=1)
                out[k] = Wall(o.normal, o.offset, _union(np.concatenate([o.segments, segs])))
                break
        else:
            out.append(w)
    return out


def _union(segs: FloatArray) -> FloatArray:
    if segs.shape[0] == 0:
        return segs
    segs = segs[np.argsort(segs[:, 0])]
    merged = [segs[0].copy()]
    for a, b in segs[1:]:
        if a <= merged[-1][1]:
            merged[-1][1] = max(merged[-1][1], b)
        else:
            merged.append(np.array([a, b]))
    return np.array(merged)


def m_step_walls(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> ObjectMap:
    """Each wall: its line by weighted least squares on the points it explains (eq. 8), then its segments
    by the DP (eq. 9). A wall whose segments no longer pay for its line parameters is dropped."""
    obj_map = state.obj_map
    walls = list(obj_map.walls)
    pts = beams.points
    keep: list[bool] = []
    for j, wall in enumerate(walls):
        sel = beams.hit & (state.first.cls == WALL) & (state.first.obj == j)
        normal, offset = wall.normal, wall.offset
        if int(np.count_nonzero(state.e[sel] > 0.0)) >= 3:  # points it explains (weights all 0: no line, NaN)
            normal, offset = fit_line(pts[sel], state.e[sel])
            if normal @ wall.normal < 0.0:
                normal, offset = -normal, -offset
        current = replace(obj_map, walls=walls)
        segs, cost = wall_segments(beams, state.first, current, j, normal, offset, config.validity_prior,
                                   config.sigma_m, config.rho_length_per_m, 2.0 * config.rho_static)
        walls[j] = Wall(normal, offset, segs)
        keep.append(segs.shape[0] > 0 and cost + 2.0 * config.rho_static < 0.0)
    kept = [w for w, k in zip(walls, keep, strict=True) if k]
    return replace(obj_map, walls=merge_collinear(kept, config.collinear_angle_deg,
                                                             config.pseudo_e_sigmas * config.sigma_m))


def m_step_doors(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> ObjectMap:
    """Each door: hinge and per-pass angles by gradient descent on eq. (10) over the points it explains."""
    obj_map = state.obj_map
    pts = beams.points
    doors = []
    for i, door in enumerate(obj_map.doors):
        sel = beams.hit & (state.first.cls == DOOR) & (state.first.obj == i)
        hinge, yaws = fit_hinge_angles(door.hinge, door.yaws, pts[sel], beams.pass_index[sel], state.e[sel],
                                       config.hinge_descent_iterations)
        doors.append(Door(hinge, yaws, door.width))
    return replace(obj_map, doors=doors)


def m_step_width(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> ObjectMap:
    """The door width by the segment-length procedure (global, or per door when configured)."""
    obj_map = state.obj_map
    if not obj_map.doors:
        return obj_map
    parts = [width_gains(beams, state.first, obj_map, i, config.door_width_max_m, config.validity_prior,
                         config.sigma_m) for i in range(len(obj_map.doors))]
    if config.per_door_width:
        doors = [Door(d.hinge, d.yaws, best_width(u, g, 1, config.rho_length_per_m, config.door_width_min_m,
                                                  config.door_width_max_m, obj_map.door_width(i)))
                 for i, (d, (u, g)) in enumerate(zip(obj_map.doors, parts, strict=True))]
        return replace(obj_map, doors=doors)
    u = np.concatenate([p[0] for p in parts])
    g = np.concatenate([p[1] for p in parts])
    width = best_width(u, g, len(obj_map.doors), config.rho_length_per_m, config.door_width_min_m,
                       config.door_width_max_m, obj_map.classes.door_width_m)
    return replace(obj_map, classes=obj_map.classes.with_width(width))


def m_step_colors(beams: BeamSet, state: MapState, config: ObjectMapConfig) -> ObjectMap:
    """Class colours by ML (Sec. V)."""
    obj_map = state.obj_map
    if not obj_map.classes.has_color:
        return obj_map
    classes = ml_class_colors(obj_map.classes, beams.color, state.first.cls, state.e, config.color_var_floor,
                              config.door_color_components)
    if not obj_map.doors:  # no door seen yet: keep the door class as it is
        old = obj_map.classes
        classes = replace(classes, color_mean=np.stack([classes.color_mean[0], old.color_mean[1]]),
                          color_var=np.stack([classes.color_var[0], old.color_var[1]]),
                          door_mix_weight=old.door_mix_weight, door_mix_mean=old.door_mix_mean,
                          door_mix_var=old.door_mix_var)
    return replace(obj_map, classes=classes)


@dataclass
class EmTrace:
    """Log posterior and seconds per EM iteration (for benchmarks and reports); ``on_step``, where set, is called
    with 1 after every EM iteration and every sweep of the final wall step (a progress bar's update)."""

    log_posterior: list[float] = field(default_factory=list)
    seconds: list[float] = field(default_factory=list)
    on_step: Callable[[int], object] | None = None

    def step(self) -> None:
        """One more unit of the stage's work done."""
        if self.on_step is not None:
            self.on_step(1)


def run_em(beams: BeamSet, obj_map: ObjectMap, config: ObjectMapConfig, learn_classes: bool = True,
           iterations: int | None = None, trace: EmTrace | None = None, tolerance: float = 1e-3) -> MapState:
    """EM iterations until the log posterior stops improving; a step that lowers it is undone (the
    sub-steps are approximations, Sec. V, so each is checked)."""
    state = evaluate(beams, obj_map, config)
    for _ in range(iterations or config.em_iterations):
        t0 = time.perf_counter()
        new_map = m_step_walls(beams, state, config)
        state_w = evaluate(beams, new_map, config)
        if state_w.log_posterior >= state.log_posterior:
            state = state_w
        new_map = m_step_doors(beams, state, config)
        if learn_classes:
            new_map = m_step_width(beams, replace(state, obj_map=new_map), config)
            new_map = m_step_colors(beams, replace(state, obj_map=new_map), config)
        new_state = evaluate(beams, new_map, config)
        if trace is not None:
            trace.seconds.append(time.perf_counter() - t0)
            trace.log_posterior.append(max(new_state.log_posterior, state.log_posterior))
            trace.step()
        gain = new_state.log_posterior - state.log_posterior
        if gain > 0.0:
            state = new_state
        if gain < tolerance * max(1.0, abs(state.log_posterior)) * 1e-3:
            break
    return state
