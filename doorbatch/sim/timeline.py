"""A scenario turned into functions of time: the robot's trajectory, door angles, people, pass intervals.

Timeline of pass k: it begins at t_k; the robot stands for ``dwell_s``; doors whose angle differs from
the previous pass swing linearly to their new angles during the first ``door_swing_s`` (pass 0 starts at
its angles); the robot drives its route; it stands for ``end_dwell_s``. The pass is *stationary* from the
end of the swing to its end, except for the scenario's explicit ``changes`` (doors moving during a pass).
Door angles are piecewise linear in time between knots; the truth file stores exactly these knots.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.errors import ConfigError
from doorbatch.geometry.segments import point_segment_distance
from doorbatch.sim.motion import MotionLimits, Trajectory, new_builder, plan_path, sample_trajectory
from doorbatch.sim.scenario import DoorState, PassSpec, PersonSpec, Scenario
from doorbatch.sim.world import World, door_leaf_segments

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class PassInterval:
    """One pass in simulation time (s from the log start)."""

    name: str
    begin_s: float  # the pass begins (robot starts its dwell; doors start swinging)
    stationary_s: float  # doors have reached this pass's angles
    end_s: float


@dataclass(frozen=True)
class DoorTimeline:
    """Per door, knots (t_s, opening angle α ≥ 0 in rad) of a piecewise-linear angle; constant outside."""

    knots_t_s: tuple[FloatArray, ...]
    knots_angle_rad: tuple[FloatArray, ...]

    def angles_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """(K, D) opening angles at times ``t_s`` (K,)."""
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        cols = [np.interp(t, kt, ka) for kt, ka in zip(self.knots_t_s, self.knots_angle_rad, strict=True)]
        return np.stack(cols, axis=1) if cols else np.zeros((t.shape[0], 0))


@dataclass(frozen=True)
class People:
    """P walking people: polylines walked at constant speed (see :class:`~doorbatch.sim.scenario.PersonSpec`)."""

    names: tuple[str, ...]
    paths: tuple[FloatArray, ...]  # (N_p, 2) each
    speed_mps: FloatArray  # (P,)
    radius_m: FloatArray
    height_m: FloatArray
    start_s: FloatArray
    mode: tuple[str, ...]
    color_mean_rgb: FloatArray  # (P, 3)
    color_std_rgb: FloatArray  # (P, 3)

    @property
    def count(self) -> int:
        """Number of people."""
        return len(self.names)

    def positions_at(self, t_s: npt.ArrayLike) -> FloatArray:
        """(K, P, 2) positions at times ``t_s``; NaN where a person is not (yet, or any more) there.

        Walked distance s = speed·(t − start); ``loop`` wraps s modulo the path length L, ``pingpong``
        reflects it over 2L, ``once`` ends at L.
        """
        t = np.asarray(t_s, dtype=np.float64).reshape(-1)
        out = np.full((t.shape[0], self.count, 2), np.nan)
        for p, path in enumerate(self.paths):
            cum = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(path, axis=0).T))])
            total = float(cum[-1])
            s = self.speed_mps[p] * (t - self.start_s[p])
            present = s >= 0.0
            if self.mode[p] == "loop":
                s = np.mod(s, total)
            elif self.mode[p] == "pingpong":
                s = np.mod(s, 2 * total)
                s = np.where(s > total, 2 * total - s, s)
            else:
                present &= s <= total
            s = np.clip(s, 0.0, total)
            xy = np.stack([np.interp(s, cum, path[:, 0]), np.interp(s, cum, path[:, 1])], axis=1)
            out[:, p, :] = np.where(present[:, None], xy, np.nan)
        return out


@dataclass(frozen=True)
class Plan:
    """Everything about a simulation that is a function of time, before any sensor noise."""

    world: World
    scenario: Scenario
    trajectory: Trajectory
    passes: tuple[PassInterval, ...]
    doors: DoorTimeline
    people: People
    end_s: float


def limits_of(scenario: Scenario) -> MotionLimits:
    """Motion limits in SI units from the scenario's robot section."""
    r = scenario.robot
    return MotionLimits(r.max_speed_mps, r.max_accel_mps2, math.radians(r.max_yaw_rate_dps),
                        math.radians(r.max_yaw_accel_dps2), r.corner_radius_m, math.radians(r.max_fillet_turn_deg))


def _path_points(world: World, route: str | None, waypoints: list[tuple[float, float]] | None,
                 reverse: bool) -> tuple[FloatArray, tuple[int, ...]]:
    if route is not None:
        r = world.route(route)
        pts, through = r.points_m, r.through_doors
    else:
        pts, through = np.asarray(waypoints, dtype=np.float64).reshape(-1, 2), ()
    return (pts[::-1].copy() if reverse else pts), through


def _state_angle(state: DoorState, max_angle: float, fraction: float, rng: np.random.Generator) -> float:
    if state == "closed":
        return 0.0
    if state == "open":
        return max_angle
    if state == "partial":
        return fraction * max_angle
    return float(rng.uniform(0.0, max_angle))


def _pass_targets(world: World, scenario: Scenario, spec: PassSpec, previous: FloatArray | None,
                  through: tuple[int, ...], first: FloatArray | None, rng: np.random.Generator) -> FloatArray:
    """Opening angles a pass sets (presets, then per-door states and angles, then routes' through-doors)."""
    doors = world.doors
    frac = scenario.partial_fraction
    preset = spec.doors
    if preset == "keep":
        target = previous.copy() if previous is not None else np.zeros(doors.count)
    elif preset == "mixed":
        choice = rng.integers(0, 3, doors.count)
        target = np.choose(choice, [np.zeros(doors.count), frac * doors.max_angle_rad, doors.max_angle_rad])
    else:
        target = np.array([_state_angle(preset, m, frac, rng) for m in doors.max_angle_rad])
    for name, state in spec.door_states.items():
        i = doors.index(name)
        target[i] = _state_angle(state, float(doors.max_angle_rad[i]), frac, rng)
    for name, deg in spec.door_angles_deg.items():
        i = doors.index(name)
        if math.radians(deg) > doors.max_angle_rad[i] + 1e-9:
            raise ConfigError(f"pass {spec.name!r}: door {name} angle {deg}° exceeds its maximum "
                              f"{math.degrees(doors.max_angle_rad[i]):.1f}°")
        target[i] = math.radians(deg)
    for i in through:
        target[i] = doors.max_angle_rad[i]
    if first is not None:
        for name in scenario.fixed_doors:
            i = doors.index(name)
            if i in through and abs(first[i] - doors.max_angle_rad[i]) > 1e-9:
                raise ConfigError(f"pass {spec.name!r}: its route needs fixed door {name} open")
            target[i] = first[i]
    return target


def _people(world: World, specs: list[PersonSpec]) -> People:
    paths = tuple(_path_points(world, p.route, p.waypoints_m, p.reverse)[0] for p in specs)

    def arr(values: list[float]) -> FloatArray:
        return np.asarray(values, dtype=np.float64)

    return People(
        names=tuple(p.name or f"person{i + 1}" for i, p in enumerate(specs)),
        paths=paths,
        speed_mps=arr([p.speed_mps for p in specs]),
        radius_m=arr([p.radius_m for p in specs]),
        height_m=arr([p.height_m for p in specs]),
        start_s=arr([p.start_s for p in specs]),
        mode=tuple(p.mode for p in specs),
        color_mean_rgb=np.asarray([p.color_mean_rgb for p in specs], dtype=np.float64).reshape(-1, 3),
        color_std_rgb=np.asarray([p.color_std_rgb for p in specs], dtype=np.float64).reshape(-1, 3),
    )


def plan_scenario(world: World, scenario: Scenario, rng: np.random.Generator) -> Plan:
    """Turn a scenario into a :class:`Plan` (``rng`` draws the ``random`` and ``mixed`` door presets).

    Raises:
        ConfigError: unknown door or route names, overlapping door changes, a fixed door forced to move,
            or (when the robot's collision check is on) a path that brings the robot into a wall or leaf.
    """
    limits = limits_of(scenario)
    n_doors = world.doors.count
    first_pts, _ = _path_points(world, scenario.passes[0].route, scenario.passes[0].waypoints_m,
                                scenario.passes[0].reverse)
    lead = first_pts[1] - first_pts[0]
    builder = new_builder(float(first_pts[0, 0]), float(first_pts[0, 1]), math.atan2(lead[1], lead[0]))
    knots: list[list[tuple[float, float]]] = [[] for _ in range(n_doors)]
    passes: list[PassInterval] = []
    previous: FloatArray | None = None
    first: FloatArray | None = None
    for k, spec in enumerate(scenario.passes):
        pts, through = _path_points(world, spec.route, spec.waypoints_m, spec.reverse)
        target = _pass_targets(world, scenario, spec, previous, through, first, rng)
        begin = builder.t
        swing = 0.0
        for d in range(n_doors):
            if previous is None:
                knots[d].append((begin, float(target[d])))
            elif abs(target[d] - previous[d]) > 1e-12:
                knots[d] += [(begin, float(previous[d])), (begin + scenario.door_swing_s, float(target[d]))]
                swing = scenario.door_swing_s
        current = target.copy()
        for change in sorted(spec.changes, key=lambda c: c.at_s):
            d = world.doors.index(change.door)
            if change.door in scenario.fixed_doors:
                raise ConfigError(f"pass {spec.name!r}: door {change.door} is fixed but has a change")
            to = (math.radians(change.to_angle_deg) if change.to_angle_deg is not None else
                  _state_angle(change.to_state or "closed", float(world.doors.max_angle_rad[d]),
                               scenario.partial_fraction, rng))
            if to > world.doors.max_angle_rad[d] + 1e-9:
                raise ConfigError(f"pass {spec.name!r}: change of door {change.door} to {math.degrees(to):.1f}° "
                                  f"exceeds its maximum {math.degrees(world.doors.max_angle_rad[d]):.1f}°")
            t0 = begin + change.at_s
            if knots[d] and t0 < knots[d][-1][0] - 1e-12:
                raise ConfigError(f"pass {spec.name!r}: change of door {change.door} at {change.at_s} s overlaps "
                                  "the previous motion of that door")
            knots[d] += [(t0, float(current[d])), (t0 + change.duration_s, to)]
            current[d] = to
        builder.dwell(spec.dwell_s)
        plan_path(builder, pts, limits)
        builder.dwell(spec.end_dwell_s)
        end = max(builder.t, *(kn[-1][0] for kn in knots)) if n_doors else builder.t
        if end > builder.t:
            builder.dwell(end - builder.t)
        passes.append(PassInterval(spec.name or f"pass{k + 1}", begin, begin + swing, builder.t))
        previous = current
        first = target if first is None else first
    end_s = builder.t
    timeline = DoorTimeline(
        tuple(np.array([t for t, _ in kn] + [end_s]) for kn in knots),
        tuple(np.array([a for _, a in kn] + [kn[-1][1]]) for kn in knots),
    )
    plan = Plan(world, scenario, builder.trajectory(), tuple(passes), timeline, _people(world, scenario.people),
                end_s)
    if scenario.robot.collision_check:
        check_clearance(plan)
    return plan


def check_clearance(plan: Plan) -> None:
    """Check that the robot's disc stays clear of walls and (moving) door leaves along the whole plan.

    Raises:
        ConfigError: the first time the clearance is below the robot's radius, naming the obstacle.
    """
    sc = plan.scenario
    t = np.arange(0.0, plan.end_s + 1e-9, 1.0 / sc.robot.collision_check_rate_hz)
    poses = sample_trajectory(plan.trajectory, t)
    xy = np.stack([poses.x, poses.y], axis=1)
    static = point_segment_distance(xy, plan.world.segments)  # (K, S)
    leaves = door_leaf_segments(plan.world.doors, plan.doors.angles_at(t))  # (K, D, 2, 2)
    dist_leaf = point_segment_distance(xy, leaves) if leaves.shape[1] else np.zeros((t.size, 0))
    radius = sc.robot.radius_m - 1e-6
    bad_static = np.nonzero(static.min(axis=1, initial=np.inf) < radius)[0]
    bad_leaf = np.nonzero(dist_leaf.min(axis=1, initial=np.inf) < radius)[0]
    if bad_static.size == 0 and bad_leaf.size == 0:
        return
    k = int(min(bad_static.min(initial=t.size), bad_leaf.min(initial=t.size)))
    if k in bad_leaf:
        what = f"door {plan.world.doors.names[int(np.argmin(dist_leaf[k]))]}"
    else:
        seg = plan.world.segments[int(np.argmin(static[k]))]
        what = f"the wall segment {seg[0].round(2).tolist()}–{seg[1].round(2).tolist()}"
    pass_name = next((p.name for p in plan.passes if p.begin_s <= t[k] <= p.end_s), "?")
    raise ConfigError(f"scenario {sc.name!r}, pass {pass_name}: at t = {t[k]:.1f} s the robot at "
                      f"({xy[k, 0]:.2f}, {xy[k, 1]:.2f}) comes closer than its radius {sc.robot.radius_m} m to "
                      f"{what}; change the route or the door angles")
