"""Door-in-a-wall scenes for paper 003's experiments: one closed door, obstacles near its edges, a robot
in front of it, and what the robot's laser and camera (with a noisy detector) see from any pose.

The wall runs along y = 0 (x from −``wall_half_length_m`` to +), the closed leaf is centred at the origin,
the robot stands at y < 0. The door's true pose: centre (0, 0), normal (0, −1) toward the robot (yaw −π/2),
goal = centre + offset·normal, facing the door (yaw +π/2). Obstacles are small boxes standing in front of
the wall next to a door edge, so that laser points between the camera rays are not on the door
(paper 003, Fig. 6). Nothing here changes the shipped worlds or scenarios: worlds are built in memory.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.camera import PinholeCamera, camera_from_info, scan_in_camera
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.records import CameraInfo, Detection, Scan, Transform
from doorbatch.sim.raycast import RayBuffers
from doorbatch.sim.scenario import CameraSpec, ColorsSpec, DetectionsSpec, LaserSpec, MountSpec
from doorbatch.sim.sensors import (
    Box,
    CameraModel,
    LaserModel,
    Scene,
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
from doorbatch.sim.timeline import People
from doorbatch.sim.world import World, parse_world

FloatArray = npt.NDArray[np.float64]

# Paper 003, Sec. IV: a 360° laser at 1° resolution, a 640×480 camera with a 60° horizontal field of view.
PAPER_LASER = LaserSpec(fov_deg=360.0, beams=360, max_range_m=12.0, sigma_m=0.01)
PAPER_CAMERA = CameraSpec(width_px=640, height_px=480, hfov_deg=60.0, noise_sigma=0.0)
# Tables I and II measure the line fits and the goal updating on correctly detected doors: no missed boxes and
# no false door boxes (a confident false box is chosen over the door by Sec. III-B's rule whatever the fit);
# box centre and size noise as the simulator's detector.
PAPER_DETECTIONS = DetectionsSpec(miss_prob=0.0, false_positive_rate=0.0)
CAMERA_FRAME = "camera_optical"
NO_PEOPLE = People((), (), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), (), np.zeros((0, 3)), np.zeros((0, 3)))
LASER_FRAME = "laser"


@dataclass(frozen=True)
class DoorSceneSpec:
    """Random door scenes: door width, hinge side, obstacles near the edges (sizes and distances in m)."""

    door_width_m: tuple[float, float] = (0.8, 1.0)
    wall_half_length_m: float = 6.0
    obstacles_per_scene: tuple[int, int] = (1, 2)
    obstacle_size_m: tuple[float, float] = (0.08, 0.3)
    obstacle_from_wall_m: tuple[float, float] = (0.1, 0.5)
    obstacle_from_edge_m: tuple[float, float] = (-0.2, 0.15)  # + toward the door centre
    laser: LaserSpec = PAPER_LASER
    camera: CameraSpec = PAPER_CAMERA
    detections: DetectionsSpec = PAPER_DETECTIONS
    colors: ColorsSpec = field(default_factory=ColorsSpec)


@dataclass(frozen=True)
class DoorScene:
    """One scene: the world, its sensors, and the door's true pose."""

    world: World
    scene: Scene
    laser: LaserModel
    camera_model: CameraModel
    camera: PinholeCamera
    detections_spec: DetectionsSpec
    colors: ColorsSpec
    tf: TfBuffer  # static base_link → laser and → camera_optical
    door_width_m: float
    handle_xy: FloatArray  # (2,) handle centre on the closed leaf

    @property
    def true_center(self) -> FloatArray:
        """Door centre (0, 0)."""
        return np.zeros(2)

    @property
    def true_yaw(self) -> float:
        """Door normal toward the robot: −π/2."""
        return -math.pi / 2

    def true_goal(self, offset_m: float) -> FloatArray:
        """Goal pose (x, y, yaw): offset along the normal, facing the door."""
        return np.array([0.0, -offset_m, math.pi / 2])

    def true_handle_side(self, pose: FloatArray) -> str:
        """Side of the handle seen from a robot at ``pose`` looking at the door: the camera's right is
        (sin θ, −cos θ) for heading θ."""
        yaw = float(pose[2])
        right = np.array([math.sin(yaw), -math.cos(yaw)])
        return "right" if float(self.handle_xy @ right) > 0.0 else "left"


def _obstacles(rng: np.random.Generator, spec: DoorSceneSpec, half_width: float) -> list[dict[str, object]]:
    n = int(rng.integers(spec.obstacles_per_scene[0], spec.obstacles_per_scene[1] + 1))
    sides = rng.permutation([-1.0, 1.0])
    out: list[dict[str, object]] = []
    for k in range(n):
        side = float(sides[k % 2])
        size = float(rng.uniform(*spec.obstacle_size_m))
        inward = float(rng.uniform(*spec.obstacle_from_edge_m))
        x = side * (half_width - inward)
        y = -float(rng.uniform(*spec.obstacle_from_wall_m)) - size / 2
        out.append({"name": f"obstacle{k}", "center_m": [x, y], "size_m": [size, size],
                    "yaw_deg": float(rng.uniform(0.0, 90.0))})
    return out


def make_door_scene(rng: np.random.Generator, spec: DoorSceneSpec | None = None) -> DoorScene:
    """A random scene: door width and hinge side, obstacles near the edges (see :class:`DoorSceneSpec`)."""
    spec = spec or DoorSceneSpec()
    width = float(rng.uniform(*spec.door_width_m))
    half = width / 2
    hinge_left = bool(rng.random() < 0.5)
    door = {"name": "d01", "hinge_m": [-half if hinge_left else half, 0.0], "length_m": width,
            "closed_yaw_deg": 0.0 if hinge_left else 180.0, "opening_sign": 1 if hinge_left else -1,
            "max_angle_deg": 90.0, "material": "door"}
    w = spec.wall_half_length_m
    world = parse_world({
        "name": "door_scene",
        "materials": {"wall": {"mean_rgb": [204, 204, 198]}, "door": {"mean_rgb": [150, 104, 64]},
                      "handle": {"mean_rgb": [48, 48, 52]}, "pillar": {"mean_rgb": [90, 120, 160]}},
        "walls": [{"points_m": [[-w, 0.0], [w, 0.0]]}],
        "pillars": _obstacles(rng, spec, half),
        "doors": [door],
    })
    scene = make_scene(world, np.zeros(1), NO_PEOPLE, np.zeros((0, 2)))
    cam = camera_model(spec.camera)
    tf = TfBuffer()
    lm: MountSpec = spec.laser.mount
    half_yaw = math.radians(lm.yaw_deg) / 2
    tf.add(Transform(0, "base_link", LASER_FRAME, np.array([lm.x_m, lm.y_m, lm.z_m]),
                     np.array([0.0, 0.0, math.sin(half_yaw), math.cos(half_yaw)]), True))
    tf.add(Transform(0, "base_link", CAMERA_FRAME, np.array([cam.mount_xy_m[0], cam.mount_xy_m[1], cam.mount_z_m]),
                     camera_rotation_xyzw(cam.mount_yaw_rad), True))
    p = np.zeros((3, 4))
    p[:, :3] = cam.k
    info = CameraInfo(0, 0, CAMERA_FRAME, cam.width, cam.height, "plumb_bob", np.zeros(5), cam.k, p)
    free_end = np.array(door["hinge_m"], dtype=float) + width * np.array([1.0 if hinge_left else -1.0, 0.0])
    handle = world.doors.handle_from_free_end_m[0]
    handle_xy = free_end - handle * np.array([1.0 if hinge_left else -1.0, 0.0])
    return DoorScene(world, scene, laser_model(spec.laser), cam, camera_from_info(info), spec.detections,
                     spec.colors, tf, width, handle_xy)


@dataclass(frozen=True)
class Observation:
    """What the robot senses at one pose: detector boxes, laser hits in the camera frame, true boxes, and
    the raw image and ranges (for writing logs)."""

    detections: tuple[Detection, ...]
    points_cam: FloatArray  # (N, 3) optical frame
    handle_visible: bool  # the true boxes include the door's handle
    true_boxes: tuple[Box, ...]
    image: npt.NDArray[np.uint8]  # (H, W, 3) RGB
    ranges: npt.NDArray[np.float32]  # (B,) the scan


def observe(door_scene: DoorScene, pose: FloatArray, rng: np.random.Generator,
            buffers: RayBuffers | None = None) -> Observation:
    """Render the camera, box the visible door and handle with detector noise, and scan with the laser;
    the scan's hits go into the camera frame through the scene's TF tree."""
    ds = door_scene
    frame = render_camera(pose, ds.scene, ds.world, NO_PEOPLE, ds.camera_model, lighting_of(ds.colors), rng, buffers)
    boxes = door_boxes(pose, ds.scene, ds.world, ds.camera_model, frame, ds.detections_spec.min_visible_fraction)
    dets = tuple(Detection(c, s, x, y, w, h)
                 for c, s, x, y, w, h in noisy_detections(boxes, ds.detections_spec, ds.camera_model, rng))
    sample = simulate_scan(pose, ds.scene, ds.laser, rng, buffers)
    scan = Scan(0, 0, LASER_FRAME, ds.laser.angle_min_rad, ds.laser.angle_increment_rad, ds.laser.range_min_m,
                ds.laser.range_max_m, sample.ranges.astype(np.float32))
    points, _ = scan_in_camera(scan, ds.tf, CAMERA_FRAME)
    return Observation(dets, points, any(b.class_id == "handle" for b in boxes), tuple(boxes), frame.image,
                       scan.ranges)
