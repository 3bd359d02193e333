"""The simulator's top level: a scenario in a world → a stream of ROS 2 messages, a log, truth files.

:func:`simulate` is the library function (no file I/O): it yields ``(topic, msgtype, log_time_ns, msg)``
in log-time order. :func:`run_simulation` writes them with :class:`~doorbatch.io.log_writer.LogWriter`, plus
next to the log ``<stem>.truth.yaml`` (:mod:`doorbatch.io.sim_truth`), ``<stem>.truth.tum`` (ground-truth
trajectory, TUM), and the static truth maps ``<stem>.map_closed.yaml`` / ``<stem>.map_static.yaml``
(+ ``.pgm``), where ``<stem>`` is the log's name without ``.mcap`` / ``.bag``.

Determinism: one root ``numpy.random.Generator`` seeded with ``seed`` spawns one child stream per consumer
(scenario presets, odometry, laser, colors, camera, detections), so the same seed gives the same bytes and
switching one sensor off does not change the others' noise. Stamps start at ``start_time_s`` of the
scenario (default 1 700 000 000 s) and are exact multiples of each sensor's period; log time = header time.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

import doorbatch
from doorbatch.errors import UsageError
from doorbatch.io import ros_messages as m
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.map_server import write_map
from doorbatch.io.sim_truth import SimTruth, TruthDoor, TruthPass, output_paths, write_truth
from doorbatch.io.split import copy_window
from doorbatch.io.tum import write_tum
from doorbatch.sim.motion import OdometryNoise, PoseSamples, drift_poses, sample_trajectory, simulate_odometry
from doorbatch.sim.raycast import RayBuffers
from doorbatch.sim.scenario import Scenario, load_scenario, resolve_scenario
from doorbatch.sim.sensors import (
    beam_colors,
    camera_model,
    camera_rotation_xyzw,
    door_boxes,
    laser_model,
    lighting_of,
    make_scene,
    noisy_detections,
    render_camera,
    simulate_scan,
)
from doorbatch.sim.timeline import Plan, plan_scenario
from doorbatch.sim.truthmap import truth_maps
from doorbatch.sim.world import SurfaceKind, World, load_world

log = logging.getLogger(__name__)

NS_PER_S = 1_000_000_000
TF = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"
LASERSCAN = "sensor_msgs/msg/LaserScan"
POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
DETECTIONS = "vision_msgs/msg/Detection2DArray"
_STREAMS = ("scenario", "odometry", "laser", "colors", "camera", "detections")


class SimMessage(NamedTuple):
    """One message of the simulated log."""

    topic: str
    msgtype: str
    log_time_ns: int
    msg: Any


@dataclass(frozen=True)
class SimulationSummary:
    """What :func:`run_simulation` wrote."""

    log_path: Path
    truth_path: Path
    trajectory_path: Path
    map_closed_path: Path
    map_static_path: Path
    format: str
    seed: int
    world: str
    scenario: str
    start_ns: int
    end_ns: int
    duration_s: float
    passes: int
    doors: int
    message_counts: dict[str, int] = field(default_factory=dict)
    pass_logs: list[Path] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        """Plain data (paths as strings) for ``--json``."""
        data = {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(self).items()}
        data["pass_logs"] = [str(p) for p in self.pass_logs]
        return data


def random_streams(seed: int) -> dict[str, np.random.Generator]:
    """The per-consumer generators spawned from one root generator seeded with ``seed``."""
    children = np.random.default_rng(seed).spawn(len(_STREAMS))
    return dict(zip(_STREAMS, children, strict=True))


def sensor_stamps_ns(start_ns: int, rate_hz: float, end_s: float) -> npt.NDArray[np.int64]:
    """Stamps start + round(i·10⁹/rate) for i = 0, 1, … while i/rate ≤ end_s."""
    n = math.floor(end_s * rate_hz + 1e-9) + 1
    return np.asarray(start_ns + np.rint(np.arange(n) * (NS_PER_S / rate_hz)).astype(np.int64), dtype=np.int64)


def _seconds(stamps_ns: npt.NDArray[np.int64], start_ns: int) -> npt.NDArray[np.float64]:
    return np.asarray((stamps_ns - start_ns) / NS_PER_S, dtype=np.float64)


def odometry_noise(scenario: Scenario) -> OdometryNoise:
    """The scenario's wheel-odometry noise model (α1–α4, scale error, yaw drift) for :func:`drift_poses`."""
    o = scenario.sensors.odometry
    return OdometryNoise(o.alpha1, o.alpha2, o.alpha3, o.alpha4, o.scale_error, o.yaw_drift_rad_per_m)


def odometry_step(scenario: Scenario) -> tuple[float, float]:
    """The largest increment (m, rad) between two odometry messages of ``scenario``: the robot's top speed and
    turn rate over the odometry period."""
    rate = scenario.sensors.odometry.rate_hz
    return scenario.robot.max_speed_mps / rate, math.radians(scenario.robot.max_yaw_rate_dps) / rate


def scenario_drift(poses: npt.ArrayLike, scenario: Scenario, rng: np.random.Generator) -> npt.NDArray[np.float64]:
    """Poses (N, 3) corrupted into the wheel odometry ``scenario``'s robot would report along them: its noise
    model applied at its odometry stream's resolution (:func:`odometry_step`, :func:`drift_poses`)."""
    step_m, step_rad = odometry_step(scenario)
    return drift_poses(poses, odometry_noise(scenario), rng, step_m=step_m, step_rad=step_rad)


# --------------------------------------------------------------------------------------------- messages


class _Kind(IntEnum):
    """Event kinds of the message loop; at equal stamps they are emitted in this order."""

    STATIC = 0
    ODOM = 1
    TRUTH = 2
    LASER = 3
    CAMERA = 4


def simulate(world: World, scenario: Scenario, seed: int) -> Iterator[SimMessage]:
    """The simulated log as messages in log-time order (see the module docstring).

    Raises:
        ConfigError: the scenario does not fit the world (names, collisions; see :func:`plan_scenario`).
    """
    streams = random_streams(seed)
    plan = plan_scenario(world, scenario, streams["scenario"])
    yield from plan_messages(plan, streams)


# A leaf counts as seen in a scan when at least this many beams return from it (a short visible piece of a
# leaf is not a line a mapper could measure the door's angle from).
MIN_LEAF_BEAMS = 10


@dataclass
class LeafObservations:
    """Per pass and door (stationary interval only): laser returns on the leaf, scans in which the leaf was
    seen (≥ MIN_LEAF_BEAMS returns), and the range of signed door angles over those scans."""

    windows_ns: npt.NDArray[np.int64]  # (P, 2) stationary_ns, end_ns
    opening_sign: npt.NDArray[np.float64]  # (D,)
    hits: npt.NDArray[np.int64] = field(init=False)
    scans: npt.NDArray[np.int64] = field(init=False)
    angle_min: npt.NDArray[np.float64] = field(init=False)
    angle_max: npt.NDArray[np.float64] = field(init=False)

    def __post_init__(self) -> None:
        shape = (self.windows_ns.shape[0], self.opening_sign.shape[0])
        self.hits = np.zeros(shape, dtype=np.int64)
        self.scans = np.zeros(shape, dtype=np.int64)
        self.angle_min = np.full(shape, np.inf)
        self.angle_max = np.full(shape, -np.inf)

    def add(self, stamp_ns: int, surface: npt.NDArray[np.int64], n_static: int,
            angles_rad: npt.NDArray[np.float64]) -> None:
        """Count one scan's returns per leaf (``surface`` indices n_static … n_static + D − 1 are leaves)."""
        inside = np.flatnonzero((self.windows_ns[:, 0] <= stamp_ns) & (stamp_ns < self.windows_ns[:, 1]))
        if not inside.size:
            return
        k = int(inside[0])
        n_doors = self.opening_sign.shape[0]
        leaf = surface[(surface >= n_static) & (surface < n_static + n_doors)] - n_static
        counts = np.bincount(leaf, minlength=n_doors)
        self.hits[k] += counts
        seen = counts >= MIN_LEAF_BEAMS
        signed = self.opening_sign * angles_rad
        self.scans[k] += seen
        self.angle_min[k] = np.where(seen, np.minimum(self.angle_min[k], signed), self.angle_min[k])
        self.angle_max[k] = np.where(seen, np.maximum(self.angle_max[k], signed), self.angle_max[k])

    def rows(self) -> list[list[float]]:
        """[pass, door_id, laser_hits, scans_seen, angle_min, angle_max] for every pass and door seen."""
        out = []
        for k, d in zip(*np.nonzero(self.scans), strict=True):
            out.append([int(k), int(d), int(self.hits[k, d]), int(self.scans[k, d]), float(self.angle_min[k, d]),
                        float(self.angle_max[k, d])])
        return out


def plan_messages(plan: Plan, streams: dict[str, np.random.Generator],
                  observations: LeafObservations | None = None) -> Iterator[SimMessage]:
    """Messages of a planned simulation, drawing noise from ``streams`` (see :func:`random_streams`);
    ``observations`` (if given) collects which door leaves the laser saw."""
    sc = plan.scenario
    s = sc.sensors
    start = sc.start_time_s * NS_PER_S
    base = sc.base_frame_id
    events: list[tuple[npt.NDArray[np.int64], int]] = [(np.array([start], dtype=np.int64), _Kind.STATIC)]
    rates = {_Kind.ODOM: (s.odometry.enabled, s.odometry.rate_hz), _Kind.TRUTH: (s.ground_truth.enabled,
             s.ground_truth.rate_hz), _Kind.LASER: (s.laser.enabled, s.laser.rate_hz),
             _Kind.CAMERA: (s.camera.enabled, s.camera.rate_hz)}
    stamps = {k: sensor_stamps_ns(start, rate, plan.end_s) for k, (on, rate) in rates.items() if on}
    events += [(st, k) for k, st in stamps.items()]
    all_stamps = np.concatenate([st for st, _ in events])
    all_kinds = np.concatenate([np.full(st.shape[0], k) for st, k in events])
    all_index = np.concatenate([np.arange(st.shape[0]) for st, _ in events])
    order = np.lexsort((all_kinds, all_stamps))

    truth = {k: sample_trajectory(plan.trajectory, _seconds(st, start)) for k, st in stamps.items()}
    odom: PoseSamples | None = None
    if _Kind.ODOM in truth:
        t0 = truth[_Kind.ODOM]
        origin = (0.0, 0.0, 0.0) if s.odometry.start_at_origin else (float(t0.x[0]), float(t0.y[0]),
                                                                         float(t0.yaw[0]))
        odom = simulate_odometry(t0, odometry_noise(sc), streams["odometry"], origin)
    sensing = {k: _scene_inputs(plan, _seconds(st, start)) for k, st in stamps.items()
               if k in (_Kind.LASER, _Kind.CAMERA)}
    laser = laser_model(s.laser)
    cam = camera_model(s.camera)
    lighting = lighting_of(s.colors)
    buffers = RayBuffers()
    beam_times = np.linspace(0.0, s.laser.sweep_s, laser.beams)  # s after the stamp (the first beam's time)

    for e in order:
        kind, i = int(all_kinds[e]), int(all_index[e])
        t = int(all_stamps[e])
        if kind == _Kind.STATIC:
            yield from _static_tf(sc, t, base)
        elif kind == _Kind.ODOM and odom is not None:
            o = s.odometry
            x, y, yaw = float(odom.x[i]), float(odom.y[i]), float(odom.yaw[i])
            yield SimMessage(o.topic, ODOMETRY, t, m.odometry(t, o.frame_id, o.child_frame_id, x, y, yaw,
                                                                float(odom.v_mps[i]), float(odom.w_rps[i])))
            if o.publish_tf:
                yield SimMessage("/tf", TF, t, m.tf_message([m.planar_transform(t, o.frame_id, o.child_frame_id,
                                                                                 x, y, yaw)]))
        elif kind == _Kind.TRUTH:
            g, p = s.ground_truth, truth[_Kind.TRUTH]
            yield SimMessage(g.topic, ODOMETRY, t, m.odometry(t, g.frame_id, base, float(p.x[i]), float(p.y[i]),
                                                                float(p.yaw[i]), float(p.v_mps[i]),
                                                                float(p.w_rps[i])))
        elif kind == _Kind.LASER:
            p = truth[_Kind.LASER]
            angles, people_xy = sensing[_Kind.LASER]
            scene = make_scene(plan.world, angles[i], plan.people, people_xy[i])
            pose = np.array([p.x[i], p.y[i], p.yaw[i]])
            if s.laser.sweep_s > 0.0:  # each beam from where the robot is at its time (a rotating laser)
                swept = sample_trajectory(plan.trajectory, _seconds(np.array([t]), start)[0] + beam_times)
                pose = np.stack([swept.x, swept.y, swept.yaw], axis=1)
            sample = simulate_scan(pose, scene, laser, streams["laser"], buffers)
            if observations is not None:
                observations.add(t, sample.surface, scene.n_static, angles[i])
            yield SimMessage(s.laser.topic, LASERSCAN, t, m.laser_scan(
                t, s.laser.frame_id, laser.angle_min_rad, laser.angle_increment_rad, laser.range_min_m,
                laser.range_max_m, sample.ranges.astype(np.float32), scan_time_s=1.0 / s.laser.rate_hz,
                time_increment_s=s.laser.sweep_s / (laser.beams - 1)))
            if s.colors.enabled:
                points, rgb = beam_colors(sample, scene, laser, s.colors, streams["colors"])
                yield SimMessage(s.colors.topic, POINTCLOUD2, t,
                                 m.pointcloud_xyzrgb(t, s.laser.frame_id, points, rgb, is_dense=False))
        elif kind == _Kind.CAMERA:
            p = truth[_Kind.CAMERA]
            angles, people_xy = sensing[_Kind.CAMERA]
            scene = make_scene(plan.world, angles[i], plan.people, people_xy[i])
            pose = np.array([p.x[i], p.y[i], p.yaw[i]])
            frame = render_camera(pose, scene, plan.world, plan.people, cam, lighting, streams["camera"], buffers)
            c = s.camera
            yield SimMessage(c.info_topic, CAMERA_INFO, t, m.camera_info(t, c.frame_id, cam.width, cam.height, cam.k))
            yield SimMessage(c.image_topic, IMAGE, t, m.image_rgb8(t, c.frame_id, frame.image))
            if s.detections.enabled:
                boxes = door_boxes(pose, scene, plan.world, cam, frame, s.detections.min_visible_fraction)
                dets = noisy_detections(boxes, s.detections, cam, streams["detections"])
                yield SimMessage(s.detections.topic, DETECTIONS, t, m.detection_array(t, c.frame_id, dets))


def _scene_inputs(plan: Plan, t_s: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Door opening angles (K, D) and people positions (K, P, 2) at the given times."""
    return plan.doors.angles_at(t_s), plan.people.positions_at(t_s)


def _static_tf(sc: Scenario, stamp_ns: int, base: str) -> Iterator[SimMessage]:
    s = sc.sensors
    transforms = []
    if s.laser.enabled:
        lm = s.laser.mount
        transforms.append(m.planar_transform(stamp_ns, base, s.laser.frame_id, lm.x_m, lm.y_m,
                                             math.radians(lm.yaw_deg), z=lm.z_m))
    if s.camera.enabled:
        cm = s.camera.mount
        q = camera_rotation_xyzw(math.radians(cm.yaw_deg))
        transforms.append(m.transform_stamped(stamp_ns, base, s.camera.frame_id, (cm.x_m, cm.y_m, cm.z_m),
                                              tuple(float(v) for v in q)))
    if transforms:
        yield SimMessage("/tf_static", TF, stamp_ns, m.tf_message(transforms))


# --------------------------------------------------------------------------------------------- files


def run_simulation(world_path: Path, out: Path, scenario: str | Path | None = None, seed: int = 0,
                   fmt: str = "mcap", map_resolution_m: float = 0.05, split_passes: bool = False
                   ) -> SimulationSummary:
    """Simulate ``scenario`` (a shipped name, a path, or None for ``default``) in the world file and write
    the log at ``out`` in ``fmt`` (mcap, bag, rosbag2, rosbag2-mcap) with its truth files beside it.
    With ``split_passes``, each pass's stationary interval (doors still) is also written as its own log,
    ``<stem>_pass<k><suffix>``, because ``doorbatch map`` takes one log per pass.

    Raises:
        ConfigError: bad world or scenario file, or a scenario that does not fit the world.
        UsageError: an unknown format.
        OSError: an output file cannot be written.
    """
    world = load_world(Path(world_path))
    scenario_file = resolve_scenario(scenario)
    sc = load_scenario(scenario_file)
    log_format = LogFormat(fmt) if fmt in {f.value for f in LogFormat} else _bad_format(fmt)
    paths = output_paths(out)
    streams = random_streams(seed)
    plan = plan_scenario(world, sc, streams["scenario"])
    counts: dict[str, int] = {}
    start = sc.start_time_s * NS_PER_S
    observations = LeafObservations(
        np.array([[start + round(p.stationary_s * NS_PER_S), start + round(p.end_s * NS_PER_S)] for p in plan.passes],
                 dtype=np.int64).reshape(-1, 2),
        world.doors.opening_sign.astype(np.float64))
    with LogWriter(paths["log"], log_format) as writer:
        for msg in plan_messages(plan, streams, observations):
            writer.write(msg.topic, msg.msgtype, msg.log_time_ns, msg.msg)
            counts[msg.topic] = counts.get(msg.topic, 0) + 1
    gt = sensor_stamps_ns(start, sc.sensors.ground_truth.rate_hz, plan.end_s)
    poses = sample_trajectory(plan.trajectory, _seconds(gt, start))
    write_tum(paths["trajectory"], gt, poses.x, poses.y, poses.yaw)
    closed, static = truth_maps(world, (float(poses.x[0]), float(poses.y[0])), map_resolution_m)
    write_map(closed, paths["map_closed"])
    write_map(static, paths["map_static"])
    generator = {"doorbatch_version": doorbatch.__version__, "world": world.name, "world_file": str(world_path),
                 "scenario": sc.name, "scenario_file": str(scenario_file), "seed": int(seed)}
    write_truth(truth_of(plan, generator, {k: p.name for k, p in paths.items()}, observations), paths["truth"])
    end = start + round(plan.end_s * NS_PER_S)
    pass_logs = _split_passes(paths["log"], plan, start, log_format) if split_passes else []
    summary = SimulationSummary(paths["log"], paths["truth"], paths["trajectory"], paths["map_closed"],
                                paths["map_static"], log_format.value, int(seed), world.name, sc.name, start, end,
                                float(plan.end_s), len(plan.passes), world.doors.count, dict(sorted(counts.items())),
                                pass_logs)
    log.info("simulated %s / %s: %.1f s, %d messages → %s", world.name, sc.name, plan.end_s, sum(counts.values()),
             paths["log"])
    return summary


def _split_passes(log_path: Path, plan: Plan, start_ns: int, fmt: LogFormat) -> list[Path]:
    """One log per pass, cut from the whole log at the pass's stationary interval."""
    outs = []
    for k, window in enumerate(plan.passes, start=1):
        stem, suffix = (log_path.stem, log_path.suffix) if log_path.suffix else (log_path.name, "")
        out = log_path.with_name(f"{stem}_pass{k}{suffix}")
        begin = start_ns + round(window.stationary_s * NS_PER_S)
        end = start_ns + round(window.end_s * NS_PER_S)
        copy_window(log_path, out, begin, end, fmt)
        outs.append(out)
    return outs


def _bad_format(fmt: str) -> LogFormat:
    raise UsageError(f"unknown log format {fmt!r} (use one of: {', '.join(f.value for f in LogFormat)})")


def truth_of(plan: Plan, generator: dict[str, Any], files: dict[str, str],
             observations: LeafObservations | None = None) -> SimTruth:
    """The truth record of a plan (door fields as in doors.parquet, signed angles, ns stamps)."""
    world, sc = plan.world, plan.scenario
    start = sc.start_time_s * NS_PER_S
    d = world.doors

    def ns(t_s: float) -> int:
        return start + round(t_s * NS_PER_S)

    doors = tuple(
        TruthDoor(i, d.names[i], float(d.hinge_xy[i, 0]), float(d.hinge_xy[i, 1]), float(d.length_m[i]),
                  float(d.closed_yaw_rad[i]), int(d.opening_sign[i]), float(d.max_angle_rad[i]), float(d.height_m[i]),
                  _rgb(d.color_mean_rgb[i]), _rgb(d.color_std_rgb[i]),
                  {"height": float(d.handle_height_m[i]), "from_free_end": float(d.handle_from_free_end_m[i]),
                   "width": float(d.handle_size_m[i, 0]), "size_z": float(d.handle_size_m[i, 1])}
                  if d.has_handle[i] else None)
        for i in range(d.count)
    )
    stamps, ids, angles = [], [], []
    for i, (kt, ka) in enumerate(zip(plan.doors.knots_t_s, plan.doors.knots_angle_rad, strict=True)):
        keep = np.ones(kt.shape[0], dtype=bool)  # drop knots that repeat the previous one
        keep[1:] = (np.diff(kt) > 0) | (np.diff(ka) != 0)
        for t, a in zip(kt[keep], ka[keep], strict=True):
            stamps.append(ns(float(t)))
            ids.append(i)
            angles.append(float(d.opening_sign[i] * a))
    s = sc.sensors
    cam = camera_model(s.camera)
    sensors = {
        "laser": {"frame_id": s.laser.frame_id, "x": s.laser.mount.x_m, "y": s.laser.mount.y_m,
                  "z": s.laser.mount.z_m, "yaw": math.radians(s.laser.mount.yaw_deg)},
        "camera": {"frame_id": s.camera.frame_id, "x": s.camera.mount.x_m, "y": s.camera.mount.y_m,
                   "z": s.camera.mount.z_m, "yaw": math.radians(s.camera.mount.yaw_deg), "width": cam.width,
                   "height": cam.height, "k": [float(v) for v in cam.k.ravel()]},
    }
    people = tuple(
        {"name": plan.people.names[p], "radius": float(plan.people.radius_m[p]),
         "height": float(plan.people.height_m[p]), "speed": float(plan.people.speed_mps[p]),
         "start_ns": ns(float(plan.people.start_s[p])), "mode": plan.people.mode[p],
         "path": [[float(x), float(y)] for x, y in plan.people.paths[p]]}
        for p in range(plan.people.count)
    )
    return SimTruth(
        generator=generator, start_ns=start, end_ns=ns(plan.end_s), files=files, world_name=world.name,
        wall_height_m=world.wall_height_m, segments=world.segments,
        segment_kinds=tuple(SurfaceKind(int(k)).name.lower() for k in world.segment_kind), doors=doors,
        passes=tuple(TruthPass(k, p.name, ns(p.begin_s), ns(p.stationary_s), ns(p.end_s))
                     for k, p in enumerate(plan.passes)),
        angle_stamp_ns=np.asarray(stamps, dtype=np.int64), angle_door_id=np.asarray(ids, dtype=np.int64),
        angle_rad=np.asarray(angles, dtype=np.float64), people=people, sensors=sensors,
        scenario=sc.model_dump(mode="json"),
        leaf_observations=tuple(tuple(r) for r in observations.rows()) if observations is not None else (),
    )


def _rgb(v: npt.NDArray[np.float64]) -> tuple[float, float, float]:
    return float(v[0]), float(v[1]), float(v[2])

