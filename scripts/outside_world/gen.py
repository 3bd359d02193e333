#!/usr/bin/env python3
"""Outside-world simulator: a 2D office written independently of doorbatch, rendered to ROS bags.

The world is a 30 × 14 m office: a 2 m wide corridor (walls at y = 6 and y = 8) with four rooms
off it, four hinged doors (A, B, C, D) with 0.9 m long, 4 cm thick leaves, three of them recessed
6 cm into their room behind short jambs and one (C) flush with the wall, a doorless opening into
room R1, a 0.4 m square pillar, a desk and a cabinet, and in some logs a person (a 0.175 m radius
cylinder) walking up and down the corridor. A differential-drive robot follows waypoints; its
laser (541 beams, 270°, 0.5° steps, 25 m, σ = 1.5 cm, 3 % dropouts, 10 Hz) is mounted upside down
(roll π) 0.2 m ahead of base_link; its odometry drifts (1.5 % scale error, 0.2°/m yaw bias, noise).

Each log is a ROS 2 bag folder (sqlite3) ``OUT/logs/NAME`` with /scan, /odom, /tf (odom →
base_footprint), /tf_static (base_footprint → base_link → laser) and /ground_truth (nav_msgs/Odometry
in the world frame "map"), plus ``OUT/truth/NAME.json`` (door angles, door hinges, start pose),
``OUT/truth/NAME.tum`` (true base_footprint poses at 50 Hz) and ``OUT/truth/NAME.person.npy``
(t, x, y of the person at each scan) when the log has a person.

This simulator is deliberately independent of ``doorbatch.sim`` (it uses numpy and rosbags only
and imports nothing from doorbatch): it is a second, separately written world against which
doorbatch's physics, frame conventions and bag reading are checked. The numbers (world, routes,
seeds, time stamps) are those of the colleague's original generator, so its logs, and the figures
computed from them, are reproduced byte for byte.

Logs: pass1, pass2, pass3 (the mapping passes; doors A, B, C at different angles in each, D at 80°
in all, a person in pass2), loc_closed (all doors closed), loc_partial (doors part-open, a person).
With ``--variants`` (or by name with ``--logs``) also: pass1_ros1 (pass1 as a ROS 1 bag),
pass1_neginc (pass1 with an upright laser whose ranges run with a negative angle increment),
loc_closed_tfonly (loc_closed without /odom), and v_partial_noperson, v_closed_sameroute,
v_partial_D80 (loc_partial's route with other door angles and no person).

Reproducing the figures (from the repository root; DIR is the --out folder)::

    python scripts/outside_world/gen.py --out DIR
    doorbatch map DIR/logs/pass1 DIR/logs/pass2 DIR/logs/pass3 -o MAP
    doorbatch map DIR/logs/pass1 DIR/logs/pass2 DIR/logs/pass3 -o MAP_EM --stages grid,em
    python scripts/outside_world/score.py map MAP --world DIR
    doorbatch localize DIR/logs/loc_partial --map MAP -o RUN --method rbpf
    doorbatch localize DIR/logs/loc_partial --map MAP -o RUN_MCL --method mcl
    doorbatch localize DIR/logs/loc_partial --map MAP -o RUN_GLOBAL --method rbpf --init global
    doorbatch localize DIR/logs/loc_closed --map MAP -o RUN_CLOSED --method rbpf
    python scripts/outside_world/score.py run RUN loc_partial --world DIR
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

DEFAULT_OUT = Path("/tmp/outside_world")

# ---------------------------------------------------------------- world
WORLD_W_M, WORLD_H_M = 30.0, 14.0
CORRIDOR_Y0_M, CORRIDOR_Y1_M = 6.0, 8.0  # lower and upper corridor walls
LEAF_M = 0.9  # door leaf length, hinge to free end
LEAF_THICK_M = 0.04

# Each door: hinge (x, y); closed_yaw (direction hinge → free end when closed); sign (+1 if opening into
# the room turns the leaf CCW); gap (doorway x range in the wall); wall_y (the wall line); side (+1: room
# above the corridor, -1: below). Hinges 0.06 m off the wall line sit in a recess behind jambs.
DOORS: dict[str, dict[str, Any]] = {
    # A: upper room R1, doorway x in [4.0, 4.9] on y=8, hinge at x=4.0, closed towards +x, opens into +y (CCW)
    "A": dict(hinge=(4.0, 8.0 + 0.06), closed_yaw=0.0, sign=+1, gap=(4.0, 4.9), wall_y=8.0, side=+1),
    # B: lower room R2, doorway x in [7.0, 7.9] on y=6, hinge at x=7.9, closed towards -x, opens into -y (CCW)
    "B": dict(hinge=(7.9, 6.0 - 0.06), closed_yaw=math.pi, sign=+1, gap=(7.0, 7.9), wall_y=6.0, side=-1),
    # C: upper room R3, doorway x in [24.0, 24.9] on y=8, hinge x=24.9, closed towards -x, flush, opens into +y (CW)
    "C": dict(hinge=(24.9, 8.0), closed_yaw=math.pi, sign=-1, gap=(24.0, 24.9), wall_y=8.0, side=+1),
    # D: lower room R4, doorway x in [17.0, 17.9] on y=6, hinge x=17.0, closed +x, opens into -y (CW)
    "D": dict(hinge=(17.0, 6.0 - 0.06), closed_yaw=0.0, sign=-1, gap=(17.0, 17.9), wall_y=6.0, side=-1),
}
RECESSED_DOORS = ("A", "B", "D")
JAMB_DEPTH_M = 0.10
OPEN_GAP_R1 = (8.0, 9.0)  # a doorless opening into R1 (upper) the robot pokes through
PILLAR = (6.5, 11.0, 0.4)  # centre x, y, side (room R1)
PERSON_RADIUS_M = 0.175


def outer_walls() -> list[tuple[float, float, float, float]]:
    """The building's four outer walls as (x0, y0, x1, y1) segments."""
    W, H = WORLD_W_M, WORLD_H_M
    return [(0, 0, W, 0), (W, 0, W, H), (W, H, 0, H), (0, H, 0, 0)]


def corridor_walls() -> list[tuple[float, float, float, float]]:
    """The two corridor walls, interrupted by the doorways and the open gap into R1."""
    segs: list[tuple[float, float, float, float]] = []
    gaps_up = sorted([DOORS["A"]["gap"], OPEN_GAP_R1, DOORS["C"]["gap"]])
    gaps_lo = sorted([DOORS["B"]["gap"], DOORS["D"]["gap"]])
    for y, gaps in ((CORRIDOR_Y1_M, gaps_up), (CORRIDOR_Y0_M, gaps_lo)):
        x = 0.0
        for g0, g1 in gaps:
            segs.append((x, y, g0, y))
            x = g1
        segs.append((x, y, WORLD_W_M, y))
    return segs


def room_walls_and_furniture() -> list[tuple[float, float, float, float]]:
    """Room dividers (upper: R1 [0,10], storage [10,20], R3 [20,30]; lower: R2 [0,12], R4 [12,24],
    closed [24,30]), a cabinet in R3 and a desk in R2."""
    segs: list[tuple[float, float, float, float]] = [
        (10.0, CORRIDOR_Y1_M, 10.0, WORLD_H_M), (20.0, CORRIDOR_Y1_M, 20.0, WORLD_H_M)]
    segs += [(12.0, 0.0, 12.0, CORRIDOR_Y0_M), (24.0, 0.0, 24.0, CORRIDOR_Y0_M)]
    segs += [(27.0, 12.5, 29.0, 12.5), (29.0, 12.5, 29.0, 13.0), (27.0, 12.5, 27.0, 13.0)]
    segs += [(2.0, 1.0, 4.0, 1.0), (4.0, 1.0, 4.0, 1.8), (4.0, 1.8, 2.0, 1.8), (2.0, 1.8, 2.0, 1.0)]
    return segs


def door_jambs() -> list[tuple[float, float, float, float]]:
    """Short jamb segments from the wall line into the room at both edges of each recessed doorway."""
    segs: list[tuple[float, float, float, float]] = []
    for name in RECESSED_DOORS:
        d = DOORS[name]
        for gx in d["gap"]:
            segs.append((gx, d["wall_y"], gx, d["wall_y"] + d["side"] * JAMB_DEPTH_M))
    return segs


def pillar_walls() -> list[tuple[float, float, float, float]]:
    """The four faces of the square pillar in R1."""
    px, py, s = PILLAR
    h = s / 2
    return [(px - h, py - h, px + h, py - h), (px + h, py - h, px + h, py + h),
            (px + h, py + h, px - h, py + h), (px - h, py + h, px - h, py - h)]


def static_segments() -> FloatArray:
    """Every wall of the world that never moves (no door leaves), as an (M, 4) array of x0, y0, x1, y1."""
    segs = outer_walls() + corridor_walls() + room_walls_and_furniture() + door_jambs() + pillar_walls()
    return np.array(segs, float)


def leaf_segments(name: str, angle_deg: float) -> FloatArray:
    """Door ``name``'s leaf, open ``angle_deg`` (≥ 0) into its room, as the 4 sides of a thin rectangle."""
    d = DOORS[name]
    hx, hy = d["hinge"]
    yaw = d["closed_yaw"] + d["sign"] * math.radians(angle_deg)
    ux, uy = math.cos(yaw), math.sin(yaw)
    nx, ny = -uy, ux
    t = LEAF_THICK_M / 2
    p = [(hx + nx * t, hy + ny * t), (hx + ux * LEAF_M + nx * t, hy + uy * LEAF_M + ny * t),
         (hx + ux * LEAF_M - nx * t, hy + uy * LEAF_M - ny * t), (hx - nx * t, hy - ny * t)]
    return np.array([(*p[i], *p[(i + 1) % 4]) for i in range(4)], float)


# ---------------------------------------------------------------- robot motion
def _step(x: float, y: float, th: float, v: float, w: float, dt_s: float) -> tuple[float, float, float]:
    """Unicycle pose after ``dt_s`` at forward speed ``v`` and turn rate ``w`` (explicit Euler)."""
    return x + v * math.cos(th) * dt_s, y + v * math.sin(th) * dt_s, th + w * dt_s


def drive(waypoints: Sequence[tuple[float, float]], start_yaw_rad: float, dt_s: float = 0.02,
          vmax_m_s: float = 0.45, wmax_rad_s: float = 0.9, acc_m_s2: float = 0.5,
          wacc_rad_s2: float = 1.5) -> FloatArray:
    """True trajectory of a robot steering through ``waypoints`` (from the first), then braking to a stop.

    Returns an (N, 6) array of rows (t_s, x_m, y_m, yaw_rad, v_m_s, w_rad_s) at ``dt_s`` steps.
    """
    x, y = waypoints[0]
    th = start_yaw_rad
    v = w = 0.0
    out: list[tuple[float, float, float, float, float, float]] = []
    t = 0.0
    for gx, gy in waypoints[1:]:
        while True:
            dx, dy = gx - x, gy - y
            dist = math.hypot(dx, dy)
            if dist < 0.05:
                break
            err = math.atan2(dy, dx) - th
            err = (err + math.pi) % (2 * math.pi) - math.pi
            w_cmd = max(-wmax_rad_s, min(wmax_rad_s, 2.0 * err))
            v_cmd = vmax_m_s * max(0.0, math.cos(err)) ** 4
            v_cmd = min(v_cmd, 0.6 * dist + 0.05)
            if abs(err) > 0.6:
                v_cmd = 0.0
            v += max(-acc_m_s2 * dt_s, min(acc_m_s2 * dt_s, v_cmd - v))
            w += max(-wacc_rad_s2 * dt_s, min(wacc_rad_s2 * dt_s, w_cmd - w))
            out.append((t, x, y, th, v, w))
            x, y, th = _step(x, y, th, v, w, dt_s)
            t += dt_s
    for _ in range(25):  # stop smoothly
        v += max(-acc_m_s2 * dt_s, min(acc_m_s2 * dt_s, -v))
        w += max(-wacc_rad_s2 * dt_s, min(wacc_rad_s2 * dt_s, -w))
        out.append((t, x, y, th, v, w))
        x, y, th = _step(x, y, th, v, w, dt_s)
        t += dt_s
    return np.array(out)


def odometry(traj: FloatArray, rng: np.random.Generator, scale: float = 1.015, bias_deg_per_m: float = 0.2,
             sigma_v_m_s: float = 0.01, sigma_w_rad_s: float = 0.008,
             dt_s: float = 0.02) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Drifting wheel odometry of ``traj``: (N, 3) integrated poses from the odom origin, and the measured
    speeds v (m/s) and turn rates w (rad/s). Noise is drawn only while the robot moves."""
    n = len(traj)
    v = traj[:, 4] * scale + rng.normal(0, sigma_v_m_s, n) * (np.abs(traj[:, 4]) > 1e-4)
    w = traj[:, 5] + math.radians(bias_deg_per_m) * traj[:, 4] + rng.normal(0, sigma_w_rad_s, n) * (
        (np.abs(traj[:, 4]) > 1e-4) | (np.abs(traj[:, 5]) > 1e-4))
    o = np.zeros((n, 3))
    for i in range(1, n):
        x, y, th = o[i - 1]
        o[i] = (x + v[i - 1] * math.cos(th) * dt_s, y + v[i - 1] * math.sin(th) * dt_s, th + w[i - 1] * dt_s)
    return o, v, w


# ---------------------------------------------------------------- laser
N_BEAMS = 541
ANG_MIN_RAD = math.radians(-135.0)
ANG_INC_RAD = math.radians(0.5)
RANGE_MAX_M = 25.0
RANGE_MIN_M = 0.05
RANGE_SIGMA_M = 0.015
DROPOUT_PROBABILITY = 0.03
LASER_X_M = 0.2  # laser position ahead of base_link
SCAN_EVERY_N_STEPS = 5  # 10 Hz scans at the 50 Hz simulation step
STEP_NS = 20_000_000


def cast(ox: float, oy: float, dirs: FloatArray, segs: FloatArray,
         circles: Iterable[tuple[float, float, float]]) -> FloatArray:
    """Ranges (N,) of rays from (ox, oy) along unit ``dirs`` (N, 2) to the nearest of the segments ``segs``
    (M, 4) and circles (cx, cy, r); inf where a ray hits nothing."""
    dx, dy = dirs[:, 0:1], dirs[:, 1:2]
    x0, y0, x1, y1 = segs[:, 0], segs[:, 1], segs[:, 2], segs[:, 3]
    ex, ey = x1 - x0, y1 - y0
    denom = dx * ey - dy * ex  # (N,M)
    wx, wy = x0 - ox, y0 - oy
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (wx * ey - wy * ex) / denom
        u = (wx * dy - wy * dx) / denom
    ok = (np.abs(denom) > 1e-12) & (t > 1e-6) & (u >= 0) & (u <= 1)
    t = np.where(ok, t, np.inf)
    r: FloatArray = t.min(axis=1)
    for cx, cy, rad in circles:
        fx, fy = ox - cx, oy - cy
        b = dirs[:, 0] * fx + dirs[:, 1] * fy
        c = fx * fx + fy * fy - rad * rad
        disc = b * b - c
        hit = disc >= 0
        tt = np.where(hit, -b - np.sqrt(np.where(hit, disc, 0)), np.inf)
        tt = np.where(tt > 1e-6, tt, np.inf)
        r = np.minimum(r, tt)
    return r


@dataclass(frozen=True)
class PersonWalk:
    """A person walking back and forth along y ≈ ``y_m`` between ``x0_m`` and ``x1_m`` (sways ±5 cm)."""

    y_m: float
    x0_m: float
    x1_m: float
    speed_m_s: float
    phase_m: float  # distance already walked at t = 0

    def position(self, t_s: float) -> tuple[float, float]:
        """Centre (x, y) of the person at ``t_s`` seconds into the log."""
        L = self.x1_m - self.x0_m
        s = (t_s * self.speed_m_s + self.phase_m) % (2 * L)
        x = self.x0_m + s if s < L else self.x1_m - (s - L)
        return x, self.y_m + 0.05 * math.sin(1.3 * t_s)


# ---------------------------------------------------------------- ros writing
def quat_yaw(yaw_rad: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a rotation by ``yaw_rad`` about z."""
    return (0.0, 0.0, math.sin(yaw_rad / 2), math.cos(yaw_rad / 2))


class MessageFactory:
    """Builds and serializes the log's messages for one typestore: ROS 2 (CDR) or ROS 1."""

    def __init__(self, fmt: str) -> None:
        """``fmt``: "ros2" (Humble types, CDR) or "ros1" (Noetic types plus tf2_msgs/TFMessage)."""
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        self.fmt = fmt
        if fmt == "ros2":
            self.store = get_typestore(Stores.ROS2_HUMBLE)
        else:
            self.store = get_typestore(Stores.ROS1_NOETIC)
            self.store.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms",
                                                   "tf2_msgs/msg/TFMessage"))
        self.types = self.store.types

    def serialize(self, msg: Any, msgtype: str) -> bytes:
        """Message bytes in the bag format's encoding."""
        ser: Callable[[Any, str], Any] = self.store.serialize_cdr if self.fmt == "ros2" else self.store.serialize_ros1
        return bytes(ser(msg, msgtype))

    def header(self, ns: int, frame: str) -> Any:
        """std_msgs/Header stamped ``ns`` in ``frame`` (seq 0 in ROS 1)."""
        T = self.types
        stamp = T["builtin_interfaces/msg/Time"](sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))
        if self.fmt == "ros2":
            return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame)
        return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame)

    def quaternion(self, q: Sequence[float]) -> Any:
        """geometry_msgs/Quaternion from (x, y, z, w)."""
        return self.types["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3])

    def odometry(self, ns: int, frame: str, child: str, x: float, y: float, yaw: float, v: float, w: float,
                 cov: tuple[float, float, float]) -> Any:
        """nav_msgs/Odometry of a planar pose and twist; ``cov`` fills the x, y, yaw diagonal, z/roll/pitch 1e6."""
        T = self.types
        c = np.zeros(36)
        c[[0, 7, 35]] = cov
        c[[14, 21, 28]] = 1e6
        pose = T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                                           orientation=self.quaternion(quat_yaw(yaw)))
        twist = T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=v, y=0.0, z=0.0),
                                             angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=w))
        return T["nav_msgs/msg/Odometry"](
            header=self.header(ns, frame), child_frame_id=child,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=c),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=c.copy()))

    def transform(self, ns: int, parent: str, child: str, x: float, y: float, z: float,
                  q: Sequence[float]) -> Any:
        """geometry_msgs/TransformStamped parent → child."""
        T = self.types
        return T["geometry_msgs/msg/TransformStamped"](
            header=self.header(ns, parent), child_frame_id=child,
            transform=T["geometry_msgs/msg/Transform"](translation=T["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                                                       rotation=self.quaternion(q)))

    def tf_message(self, transforms: list[Any]) -> Any:
        """tf2_msgs/TFMessage holding ``transforms``."""
        return self.types["tf2_msgs/msg/TFMessage"](transforms=transforms)

    def scan(self, ns: int, ranges: NDArray[np.float32], angle_min_rad: float, angle_inc_rad: float) -> Any:
        """sensor_msgs/LaserScan in frame "laser" with the simulator's fixed range limits and 10 Hz period."""
        return self.types["sensor_msgs/msg/LaserScan"](
            header=self.header(ns, "laser"), angle_min=angle_min_rad,
            angle_max=angle_min_rad + angle_inc_rad * (N_BEAMS - 1), angle_increment=angle_inc_rad,
            time_increment=0.0, scan_time=0.1, range_min=RANGE_MIN_M, range_max=RANGE_MAX_M,
            ranges=ranges, intensities=np.zeros(0, np.float32))


Message = tuple[int, str, str, bytes]  # (stamp ns, topic, type, serialized bytes)


@dataclass(frozen=True)
class LogSpec:
    """One simulated log: route, door angles, person, noise seed, first stamp and output options."""

    name: str
    waypoints: tuple[tuple[float, float], ...]
    start_yaw_rad: float
    door_angles_deg: dict[str, int]
    person: PersonWalk | None
    seed: int
    t0_ns: int
    fmt: str = "ros2"  # "ros2": sqlite3 bag folder; "ros1": NAME.bag
    negative_increment: bool = False  # upright laser, ranges ordered +135° → -135°
    drop_topics: frozenset[str] = field(default_factory=frozenset)


def static_tf_message(mf: MessageFactory, ns: int, negative_increment: bool) -> Any:
    """/tf_static: base_footprint → base_link (z 0.1) → laser (x 0.2, z 0.3; rolled π unless upright)."""
    laser_q = (0.0, 0.0, 0.0, 1.0) if negative_increment else (1.0, 0.0, 0.0, 0.0)
    return mf.tf_message([mf.transform(ns, "base_footprint", "base_link", 0.0, 0.0, 0.1, (0, 0, 0, 1.0)),
                          mf.transform(ns, "base_link", "laser", LASER_X_M, 0.0, 0.3, laser_q)])


def simulate_scan(rng: np.random.Generator, x: float, y: float, th: float, segs: FloatArray,
                  circles: list[tuple[float, float, float]]) -> NDArray[np.float32]:
    """Noisy ranges (float32; inf beyond range, nan for dropouts) of one scan from base pose (x, y, th).

    Beam i points at base angle -(ANG_MIN + i·inc): the laser is rolled π, or (negative-increment variant)
    upright with angle_min +135° and a negative increment — the same rays either way.
    """
    lx = x + LASER_X_M * math.cos(th)
    ly = y + LASER_X_M * math.sin(th)
    base_a = -(ANG_MIN_RAD + ANG_INC_RAD * np.arange(N_BEAMS))
    dirs = np.stack([np.cos(th + base_a), np.sin(th + base_a)], 1)
    r = cast(lx, ly, dirs, segs, circles)
    r = r + rng.normal(0, RANGE_SIGMA_M, N_BEAMS)
    r = np.where(r > RANGE_MAX_M, np.inf, r)
    drop = rng.random(N_BEAMS) < DROPOUT_PROBABILITY
    return np.where(drop, np.nan, r).astype(np.float32)


def render_messages(spec: LogSpec, traj: FloatArray, odo: FloatArray, vo: FloatArray, wo: FloatArray,
                    rng: np.random.Generator, mf: MessageFactory) -> tuple[list[Message], list[tuple[float, ...]]]:
    """All messages of the log sorted by stamp, and the person's track (t, x, y) at each scan."""
    segs = np.concatenate([static_segments()]
                          + [leaf_segments(k, a) for k, a in spec.door_angles_deg.items()])
    stamps = spec.t0_ns + np.arange(len(traj), dtype=np.int64) * STEP_NS
    if spec.negative_increment:
        amin, ainc = -ANG_MIN_RAD, -ANG_INC_RAD
    else:
        amin, ainc = ANG_MIN_RAD, ANG_INC_RAD
    ser = mf.serialize
    ns0 = int(stamps[0])
    msgs: list[Message] = [(ns0, "/tf_static", "tf2_msgs/msg/TFMessage",
                            ser(static_tf_message(mf, ns0, spec.negative_increment), "tf2_msgs/msg/TFMessage"))]
    person_track: list[tuple[float, ...]] = []
    for i in range(len(traj)):
        ns = int(stamps[i])
        t, x, y, th, v, w = traj[i]
        gt = mf.odometry(ns, "map", "base_footprint", x, y, th, v, w, (1e-6, 1e-6, 1e-6))
        msgs.append((ns, "/ground_truth", "nav_msgs/msg/Odometry", ser(gt, "nav_msgs/msg/Odometry")))
        ox, oy, oth = odo[i]
        od = mf.odometry(ns, "odom", "base_footprint", ox, oy, oth, vo[i], wo[i], (1e-3, 1e-3, 1e-3))
        msgs.append((ns, "/odom", "nav_msgs/msg/Odometry", ser(od, "nav_msgs/msg/Odometry")))
        tf = mf.tf_message([mf.transform(ns, "odom", "base_footprint", ox, oy, 0.0, quat_yaw(oth))])
        msgs.append((ns, "/tf", "tf2_msgs/msg/TFMessage", ser(tf, "tf2_msgs/msg/TFMessage")))
        if i % SCAN_EVERY_N_STEPS == 0:
            circles = []
            if spec.person is not None:
                px, py = spec.person.position(t)
                circles.append((px, py, PERSON_RADIUS_M))
                person_track.append((t, px, py))
            ranges = simulate_scan(rng, x, y, th, segs, circles)
            msgs.append((ns, "/scan", "sensor_msgs/msg/LaserScan",
                         ser(mf.scan(ns, ranges, amin, ainc), "sensor_msgs/msg/LaserScan")))
    msgs.sort(key=lambda m: m[0])
    return msgs, person_track


def write_ros2_bag(path: Path, msgs: list[Message], mf: MessageFactory, drop_topics: frozenset[str]) -> None:
    """Write ``msgs`` (except ``drop_topics``) to a fresh ROS 2 sqlite3 bag folder ``path``."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    if path.exists():
        shutil.rmtree(path)
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as wr:
        conns: dict[str, Any] = {}
        for ns, topic, typ, data in msgs:
            if topic in drop_topics:
                continue
            if topic not in conns:
                conns[topic] = wr.add_connection(topic, typ, typestore=mf.store)
            wr.write(conns[topic], ns, data)


def write_ros1_bag(path: Path, msgs: list[Message], mf: MessageFactory) -> None:
    """Write ``msgs`` to a fresh ROS 1 bag ``path`` (/tf_static latched)."""
    from rosbags.rosbag1 import Writer

    if path.exists():
        path.unlink()
    with Writer(path) as wr:
        conns: dict[str, Any] = {}
        for ns, topic, typ, data in msgs:
            if topic not in conns:
                conns[topic] = wr.add_connection(topic, typ, typestore=mf.store,
                                                 latching=1 if topic == "/tf_static" else None)
            wr.write(conns[topic], ns, data)


def write_truth(out: Path, spec: LogSpec, traj: FloatArray, person_track: list[tuple[float, ...]]) -> None:
    """OUT/truth/NAME.json (door angles and geometry, start pose), NAME.tum (true poses) and NAME.person.npy."""
    truth_dir = out / "truth"
    truth = dict(name=spec.name, duration_s=float(traj[-1, 0]), door_angles_deg=spec.door_angles_deg,
                 doors={k: dict(hinge=list(v["hinge"]), closed_yaw=v["closed_yaw"], sign=v["sign"])
                        for k, v in DOORS.items()},
                 start=[float(v) for v in traj[0, 1:4]], person=spec.person is not None)
    truth_dir.mkdir(exist_ok=True, parents=True)
    (truth_dir / f"{spec.name}.json").write_text(json.dumps(truth, indent=1))
    stamps = spec.t0_ns + np.arange(len(traj), dtype=np.int64) * STEP_NS
    lines = []
    for i in range(len(traj)):
        q = quat_yaw(traj[i, 3])
        lines.append(f"{stamps[i] / 1e9:.9f} {traj[i, 1]:.6f} {traj[i, 2]:.6f} 0 {q[0]} {q[1]} {q[2]:.9f} {q[3]:.9f}\n")
    (truth_dir / f"{spec.name}.tum").write_text("".join(lines))
    if person_track:
        np.save(truth_dir / f"{spec.name}.person.npy", np.array(person_track))


def simulate_log(out: Path, spec: LogSpec) -> FloatArray:
    """Simulate one log and write its bag and truth under ``out``; returns the true trajectory."""
    rng = np.random.default_rng(spec.seed)
    traj = drive(spec.waypoints, spec.start_yaw_rad)
    odo, vo, wo = odometry(traj, rng)
    mf = MessageFactory(spec.fmt)
    msgs, person_track = render_messages(spec, traj, odo, vo, wo, rng, mf)
    (out / "logs").mkdir(parents=True, exist_ok=True)
    if spec.fmt == "ros2":
        path = out / "logs" / spec.name
        write_ros2_bag(path, msgs, mf, spec.drop_topics)
    else:
        path = out / "logs" / (spec.name + ".bag")
        write_ros1_bag(path, msgs, mf)
    write_truth(out, spec, traj, person_track)
    print(spec.name, spec.fmt, f"{traj[-1, 0]:.1f}s", len(msgs), "msgs", path)
    return traj


# ---------------------------------------------------------------- the logs
T0_NS = 1_700_000_000_000_000_000
HOUR_NS = 3_600_000_000_000
VARIANT_T0_NS = 1_700_100_000_000_000_000
MAP_ROUTE = ((2.0, 7.0), (8.5, 7.0), (8.5, 10.0), (8.5, 7.0), (17.45, 7.0), (17.45, 4.3), (17.45, 7.0),
             (28.0, 7.0), (23.0, 7.0))
CLOSED_ROUTE = ((12.0, 7.0), (3.0, 7.0), (20.0, 7.0))
PARTIAL_ROUTE = ((25.5, 6.9), (3.5, 7.0), (14.0, 7.0))
ALL_CLOSED = {"A": 0, "B": 0, "C": 0, "D": 0}
PARTIAL_OPEN = {"A": 25, "B": 65, "C": 20, "D": 40}


def base_logs() -> dict[str, LogSpec]:
    """The three mapping passes and the two localization logs, one hour apart in stamps."""
    specs = [
        LogSpec("pass1", MAP_ROUTE, 0.05, {"A": 0, "B": 90, "C": 45, "D": 80}, None, 1, 0),
        LogSpec("pass2", MAP_ROUTE, -0.03, {"A": 45, "B": 0, "C": 90, "D": 80},
                PersonWalk(y_m=6.6, x0_m=4.0, x1_m=26.0, speed_m_s=0.9, phase_m=3.0), 2, 0),
        LogSpec("pass3", MAP_ROUTE, 0.0, {"A": 90, "B": 45, "C": 0, "D": 80}, None, 3, 0),
        LogSpec("loc_closed", CLOSED_ROUTE, math.pi, dict(ALL_CLOSED), None, 11, 0),
        LogSpec("loc_partial", PARTIAL_ROUTE, math.pi, dict(PARTIAL_OPEN),
                PersonWalk(y_m=7.4, x0_m=3.0, x1_m=27.0, speed_m_s=1.1, phase_m=10.0), 12, 0),
    ]
    return {s.name: _with_t0(s, T0_NS + k * HOUR_NS) for k, s in enumerate(specs)}


def variant_logs(base: dict[str, LogSpec]) -> dict[str, LogSpec]:
    """Format and scenario variants: pass1 as ROS 1 and with a negative angle increment, loc_closed without
    /odom, and loc_partial's route (seed 12, no person) with other door angles."""
    p1, lc, lp = base["pass1"], base["loc_closed"], base["loc_partial"]
    variants = [
        _renamed(p1, "pass1_ros1", fmt="ros1"),
        _renamed(p1, "pass1_neginc", negative_increment=True),
        _renamed(lc, "loc_closed_tfonly", drop_topics=frozenset({"/odom"})),
    ]
    scenarios = {"v_partial_noperson": PARTIAL_OPEN, "v_closed_sameroute": ALL_CLOSED,
                 "v_partial_D80": {**PARTIAL_OPEN, "D": 80}}
    for k, (name, angles) in enumerate(scenarios.items()):
        variants.append(_renamed(lp, name, door_angles_deg=dict(angles), person=None,
                                 t0_ns=VARIANT_T0_NS + k * 10**12))
    return {s.name: s for s in variants}


def _with_t0(spec: LogSpec, t0_ns: int) -> LogSpec:
    """``spec`` starting at ``t0_ns``."""
    return _renamed(spec, spec.name, t0_ns=t0_ns)


def _renamed(spec: LogSpec, name: str, **changes: Any) -> LogSpec:
    """A copy of ``spec`` named ``name`` with ``changes`` applied."""
    from dataclasses import replace

    return replace(spec, name=name, **changes)


def all_logs() -> dict[str, LogSpec]:
    """Every log the simulator knows, base logs first."""
    base = base_logs()
    return {**base, **variant_logs(base)}


def select_logs(names: Sequence[str] | None, with_variants: bool) -> list[LogSpec]:
    """The logs to generate: ``names`` if given (base or variant), else the base logs (plus the variants)."""
    logs = all_logs()
    if names:
        return [logs[n] for n in names]
    base = base_logs()
    return list(logs.values()) if with_variants else list(base.values())


def main() -> None:
    """Command line: generate the selected logs under --out."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--logs", nargs="+", metavar="NAME", choices=list(all_logs()),
                        help="generate only these logs (base or variant names)")
    parser.add_argument("--variants", action="store_true",
                        help="also generate the ROS 1, negative-increment, no-/odom and door-angle variants")
    args = parser.parse_args()
    for spec in select_logs(args.logs, args.variants):
        simulate_log(args.out, spec)


if __name__ == "__main__":
    main()
