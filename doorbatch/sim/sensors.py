"""Simulated sensors: 2D laser with range noise, per-beam colors, a pinhole camera and door/handle boxes.

All sensors see a :class:`Scene`, the world at one instant (static segments, door leaves at their current
angles, people as discs), and are computed for all beams / image columns at once.

Camera model (REP 103 optical frame: z forward, x right, y down). With K = [[f_x, 0, c_x], [0, f_y, c_y],
[0, 0, 1]] a point (X, Y, Z) in the optical frame projects to u = f_x X/Z + c_x, v = f_y Y/Z + c_y (OpenCV:
the centre of pixel column i is u = i). The camera is mounted level, so every image column i is a vertical
plane: its horizontal ray (1, −(i − c_x)/f_x) in the camera's (forward, left) axes is cast in 2D, and the
ray parameter is the depth Z of what it hits. Row j at depth Z sees height h = z_cam − Z·(j − c_y)/f_y
above the floor; a surface covers the pixel when h lies within its vertical extent (walls: floor to
ceiling, leaves: floor to door height, lintels: door height to ceiling, people: floor to their height).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt
from scipy.spatial.transform import Rotation

from doorbatch.sim.raycast import RayBuffers, cast_rays, cast_rays_circles, nearest
from doorbatch.sim.scenario import CameraSpec, ColorsSpec, DetectionsSpec, LaserSpec
from doorbatch.sim.timeline import People
from doorbatch.sim.world import World, door_leaf_segments

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
UInt8Array = npt.NDArray[np.uint8]

# Rotation base_link → camera optical frame (columns: optical x = −y_body, y = −z_body, z = x_body).
OPTICAL_ROTATION = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
NEAR_PLANE_M = 0.05  # points closer than this in front of the camera are not projected
_VISIBILITY_SAMPLES = 25  # points along a leaf tested for occlusion


@dataclass(frozen=True)
class Scene:
    """The world at one instant. Surfaces are indexed static segments, then doors, then people."""

    segments: FloatArray  # (S, 2, 2) static segments
    leaves: FloatArray  # (D, 2, 2) door leaves at their current angles
    people_xy: FloatArray  # (P, 2), NaN: absent
    people_radius_m: FloatArray  # (P,)
    surface_mean: FloatArray  # (S + D + P, 3)
    surface_std: FloatArray  # (S + D + P, 3)

    @cached_property
    def obstacles(self) -> FloatArray:
        """Static segments followed by the leaves (S + D, 2, 2), in surface-index order."""
        return np.concatenate([self.segments, self.leaves])

    @property
    def n_static(self) -> int:
        """Number of static segments S."""
        return int(self.segments.shape[0])

    @property
    def n_doors(self) -> int:
        """Number of doors D."""
        return int(self.leaves.shape[0])


def make_scene(world: World, door_angles_rad: FloatArray, people: People, people_xy: FloatArray) -> Scene:
    """The scene with doors at opening angles (D,) and people at (P, 2)."""
    return Scene(
        segments=world.segments,
        leaves=door_leaf_segments(world.doors, door_angles_rad),
        people_xy=people_xy,
        people_radius_m=people.radius_m,
        surface_mean=np.concatenate([world.segment_color_mean, world.doors.color_mean_rgb, people.color_mean_rgb]),
        surface_std=np.concatenate([world.segment_color_std, world.doors.color_std_rgb, people.color_std_rgb]),
    )


def cast_scene(origin: FloatArray, directions: FloatArray, scene: Scene, buffers: RayBuffers | None = None
               ) -> tuple[FloatArray, IntArray]:
    """Nearest hit among all the scene's surfaces (static segments and leaves in one cast, then people):
    range and surface index (−1: none)."""
    hit = cast_rays(origin, directions, scene.obstacles, buffers)
    if scene.people_xy.shape[0]:
        people = cast_rays_circles(origin, directions, scene.people_xy, scene.people_radius_m)
        if people[1].max() >= 0:
            hit = nearest(hit, people, scene.n_static + scene.n_doors)
    return hit


# --------------------------------------------------------------------------------------------- laser


@dataclass(frozen=True)
class LaserModel:
    """Laser geometry and noise in SI units (from :class:`~doorbatch.sim.scenario.LaserSpec`)."""

    angle_min_rad: float
    angle_increment_rad: float
    beams: int
    range_min_m: float
    range_max_m: float
    sigma_m: float
    dropout_prob: float
    spurious_prob: float
    mount_xy_m: tuple[float, float]
    mount_z_m: float
    mount_yaw_rad: float

    @property
    def angles(self) -> FloatArray:
        """Beam angles in the laser frame (B,)."""
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.beams, dtype=np.float64)

    @cached_property
    def unit_directions(self) -> FloatArray:
        """(cos, sin) of the beam angles (B, 2), laser frame."""
        a = self.angles
        return np.stack([np.cos(a), np.sin(a)], axis=1)


def laser_model(spec: LaserSpec) -> LaserModel:
    """Beams span the field of view symmetrically; a full circle does not repeat its first beam."""
    fov = math.radians(spec.fov_deg)
    inc = fov / spec.beams if spec.fov_deg >= 360.0 else fov / (spec.beams - 1)
    return LaserModel(-fov / 2, inc, spec.beams, spec.range_min_m, spec.max_range_m, spec.sigma_m, spec.dropout_prob,
                      spec.spurious_prob, (spec.mount.x_m, spec.mount.y_m), spec.mount.z_m,
                      math.radians(spec.mount.yaw_deg))


@dataclass(frozen=True)
class ScanSample:
    """One simulated scan: beam geometry in the map frame, truth, and the measured ranges."""

    origin: FloatArray  # (2,) laser position (map); (B, 2) for a sweeping laser, each beam's own
    directions: FloatArray  # (B, 2) unit beam directions (map)
    true_range: FloatArray  # (B,) exact range to the first surface (+inf: none)
    surface: IntArray  # (B,) surface index hit (−1: none)
    ranges: FloatArray  # (B,) measured: noisy, NaN dropouts, +inf no return


def laser_rays(pose: FloatArray, model: LaserModel) -> tuple[FloatArray, FloatArray]:
    """Laser origin (2,) and unit beam directions (B, 2) in the map frame for a robot pose (x, y, yaw).

    origin = p + R(θ)·m, beam i direction = (cos, sin)(θ + yaw_mount + angle_i). For a sweeping laser ``pose`` is
    (B, 3), beam i taken from pose i: origins (B, 2), each beam from its own origin (:func:`swept_laser_rays`).
    """
    if np.ndim(pose) == 2:
        return swept_laser_rays(np.asarray(pose, dtype=np.float64), model)
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    mx, my = model.mount_xy_m
    origin = np.array([x + c * mx - s * my, y + s * mx + c * my])
    # unit directions in the laser frame, rotated by θ + yaw_mount: one (B, 2) @ (2, 2) product
    h = yaw + model.mount_yaw_rad
    ch, sh = math.cos(h), math.sin(h)
    return origin, model.unit_directions @ np.array([[ch, sh], [-sh, ch]])


def swept_laser_rays(poses: FloatArray, model: LaserModel) -> tuple[FloatArray, FloatArray]:
    """Origins (B, 2) and unit directions (B, 2) of a laser whose beam i is taken at robot pose ``poses[i]``:
    origin_i = p_i + R(θ_i)·m, direction_i = (cos, sin)(θ_i + yaw_mount + angle_i)."""
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    mx, my = model.mount_xy_m
    origins = np.stack([poses[:, 0] + c * mx - s * my, poses[:, 1] + s * mx + c * my], axis=1)
    heading = poses[:, 2] + model.mount_yaw_rad + model.angles
    return origins, np.stack([np.cos(heading), np.sin(heading)], axis=1)


def simulate_scan(pose: FloatArray, scene: Scene, model: LaserModel, rng: np.random.Generator,
                  buffers: RayBuffers | None = None) -> ScanSample:
    """Cast all beams and apply the range model of :class:`~doorbatch.sim.scenario.LaserSpec`. ``pose``: the
    robot's (3,) pose, or (B, 3) its pose at each beam's time (a sweeping laser, :func:`swept_laser_rays`).

    Draws exactly 4·B uniform/normal numbers per scan (noise, dropout, spurious, spurious range), so the
    random stream does not depend on what the beams hit.
    """
    origin, dirs = laser_rays(pose, model)
    true_range, surface = cast_scene(origin, dirs, scene, buffers)
    eps = rng.standard_normal(model.beams)
    u_drop, u_spur, u_range = rng.random((3, model.beams))
    r = true_range + model.sigma_m * eps
    if model.spurious_prob > 0.0:
        spurious = (u_spur < model.spurious_prob) & (true_range < model.range_max_m)
        r = np.where(spurious, model.range_min_m + u_range * (true_range - model.range_min_m), r)
    # no hit, or a hit (true or measured) at or beyond the maximum range: no return
    np.copyto(r, np.inf, where=(true_range >= model.range_max_m) | (r >= model.range_max_m))
    np.copyto(r, np.nan, where=u_drop < model.dropout_prob)
    return ScanSample(origin, dirs, true_range, surface, r)


# --------------------------------------------------------------------------------------------- colors


@dataclass(frozen=True)
class Lighting:
    """Brightness along the building: g(x, y) = 1 + A·sin(2π(x + y)/period + phase)."""

    amplitude: float
    period_m: float
    phase_rad: float

    def gain(self, xy: FloatArray) -> FloatArray:
        """g at points (..., 2); 1 where a coordinate is not finite."""
        g = 1.0 + self.amplitude * np.sin(2 * np.pi * (xy[..., 0] + xy[..., 1]) / self.period_m + self.phase_rad)
        return np.where(np.isfinite(g), g, 1.0)


def lighting_of(spec: ColorsSpec) -> Lighting:
    """The lighting of a colors spec."""
    return Lighting(spec.lighting_amplitude, spec.lighting_period_m, math.radians(spec.lighting_phase_deg))


def beam_colors(sample: ScanSample, scene: Scene, model: LaserModel, spec: ColorsSpec,
                rng: np.random.Generator) -> tuple[FloatArray, UInt8Array]:
    """Per-beam points (B, 3) in the laser frame (NaN for invalid beams) and colors (B, 3).

    color = clip(round(g_scan·g(hit)·(μ_s + σ_s·ε) + sigma_rgb·η)), ε, η ~ N(0, I), g_scan ~ N(1, gain_sigma²),
    for the surface s the beam hit; invalid beams get (0, 0, 0). Draws 6·B + 1 normals per scan.
    """
    valid = np.isfinite(sample.ranges) & (sample.surface >= 0)
    surf = np.maximum(sample.surface, 0)
    eps = rng.standard_normal((2, model.beams, 3))
    g_scan = 1.0 + spec.gain_sigma * float(rng.standard_normal())
    reach = np.where(np.isfinite(sample.true_range), sample.true_range, 0.0)
    hit_xy = sample.origin + reach[:, None] * sample.directions
    g = g_scan * lighting_of(spec).gain(hit_xy)
    color = g[:, None] * (scene.surface_mean[surf] + scene.surface_std[surf] * eps[0]) + spec.sigma_rgb * eps[1]
    rgb = np.where(valid[:, None], np.clip(np.rint(color), 0, 255), 0).astype(np.uint8)
    a = model.angles
    r = np.where(valid, sample.ranges, np.nan)
    points = np.stack([r * np.cos(a), r * np.sin(a), np.where(valid, 0.0, np.nan)], axis=1)
    return points, rgb


# --------------------------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics (square pixels) and the camera's mount on base_link (level, looking along yaw)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    mount_xy_m: tuple[float, float]
    mount_z_m: float
    mount_yaw_rad: float
    ambient: float
    noise_sigma: float
    exposure_sigma: float

    @property
    def k(self) -> FloatArray:
        """The 3×3 camera matrix K."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


def camera_model(spec: CameraSpec) -> CameraModel:
    """f_x = (W/2)/tan(hfov/2), f_y = f_x, principal point at the image centre ((W − 1)/2, (H − 1)/2)."""
    fx = (spec.width_px / 2) / math.tan(math.radians(spec.hfov_deg) / 2)
    return CameraModel(spec.width_px, spec.height_px, fx, fx, (spec.width_px - 1) / 2, (spec.height_px - 1) / 2,
                       (spec.mount.x_m, spec.mount.y_m), spec.mount.z_m, math.radians(spec.mount.yaw_deg),
                       spec.ambient, spec.noise_sigma, spec.exposure_sigma)


def camera_rotation_xyzw(mount_yaw_rad: float) -> FloatArray:
    """Quaternion (x, y, z, w) of base_link → optical frame: R_z(yaw) · OPTICAL_ROTATION."""
    rot = Rotation.from_euler("z", mount_yaw_rad).as_matrix() @ OPTICAL_ROTATION
    return np.asarray(Rotation.from_matrix(rot).as_quat(), dtype=np.float64)


def camera_pose(pose: FloatArray, cam: CameraModel) -> tuple[FloatArray, float]:
    """Camera position (2,) and heading in the map frame."""
    x, y, yaw = (float(v) for v in pose)
    c, s = math.cos(yaw), math.sin(yaw)
    mx, my = cam.mount_xy_m
    return np.array([x + c * mx - s * my, y + s * mx + c * my]), yaw + cam.mount_yaw_rad


def to_camera(points_xy: FloatArray, position: FloatArray, heading: float) -> tuple[FloatArray, FloatArray]:
    """Map-frame points (..., 2) → optical (X right, Z forward) of a level camera at ``position``, ``heading``."""
    d = points_xy - position
    c, s = math.cos(heading), math.sin(heading)
    forward = c * d[..., 0] + s * d[..., 1]
    left = -s * d[..., 0] + c * d[..., 1]
    return -left, forward


@dataclass(frozen=True)
class CameraFrame:
    """A rendered image and, per column, which door leaf is the front-most surface at door height."""

    image: UInt8Array  # (H, W, 3) RGB
    visible_door: IntArray  # (W,) door index, −1: none


def _incidence(dirs: FloatArray, segs: FloatArray, index: IntArray) -> FloatArray:
    """|cos| of the angle between each ray and the normal of the segment it hit (0 where none)."""
    e = segs[np.maximum(index, 0), 1] - segs[np.maximum(index, 0), 0]
    cross = dirs[:, 0] * e[:, 1] - dirs[:, 1] * e[:, 0]
    cos = np.abs(cross) / np.maximum(np.hypot(dirs[:, 0], dirs[:, 1]) * np.hypot(e[:, 0], e[:, 1]), 1e-300)
    return np.where(index >= 0, cos, 0.0)


def render_camera(pose: FloatArray, scene: Scene, world: World, people: People, cam: CameraModel,
                  lighting: Lighting, rng: np.random.Generator, buffers: RayBuffers | None = None) -> CameraFrame:
    """Flat-shaded RGB image by per-column ray casting (module docstring).

    A per-frame exposure gain ~ N(1, exposure_sigma²) scales every colour; per-pixel noise
    N(0, noise_sigma²) is added when noise_sigma > 0 (it makes images incompressible, so it is off by
    default). Draws 1 normal, plus H·W·3 with pixel noise.
    """
    position, heading = camera_pose(pose, cam)
    cols = np.arange(cam.width, dtype=np.float64)
    x_n = (cols - cam.cx) / cam.fx
    c, s = math.cos(heading), math.sin(heading)
    dirs = np.stack([c + s * x_n, s - c * x_n], axis=1)  # R(heading)·(1, −x_n): ray parameter = depth
    doors = world.doors
    closed = door_leaf_segments(doors, np.zeros(doors.count))
    wall_h = world.wall_height_m
    t_s, i_s = cast_rays(position, dirs, scene.segments, buffers)
    t_l, i_l = cast_rays(position, dirs, scene.leaves, buffers)
    t_t, i_t = cast_rays(position, dirs, closed, buffers)
    t_p, i_p = cast_rays_circles(position, dirs, scene.people_xy, scene.people_radius_m)
    il, it, ip = np.maximum(i_l, 0), np.maximum(i_t, 0), np.maximum(i_p, 0)
    n_people = people.count
    depth = np.stack([t_s, t_l, t_t, t_p])  # (4, W)
    lo = np.stack([np.zeros(cam.width), np.zeros(cam.width), doors.height_m[it] if doors.count else np.zeros(cam.width),
                   np.zeros(cam.width)])
    hi = np.stack([np.full(cam.width, wall_h), doors.height_m[il] if doors.count else np.zeros(cam.width),
                   np.full(cam.width, wall_h), people.height_m[ip] if n_people else np.zeros(cam.width)])
    hits = position + np.where(np.isfinite(depth), depth, 0.0)[..., None] * dirs  # (4, W, 2)
    gain = lighting.gain(hits)
    shade = np.stack([
        _incidence(dirs, scene.segments, i_s),
        _incidence(dirs, scene.leaves, i_l) if doors.count else np.zeros(cam.width),
        _incidence(dirs, closed, i_t) if doors.count else np.zeros(cam.width),
        np.ones(cam.width),
    ])
    shade = cam.ambient + (1.0 - cam.ambient) * shade
    base = np.stack([
        world.segment_color_mean[np.maximum(i_s, 0)],
        doors.color_mean_rgb[il] if doors.count else np.zeros((cam.width, 3)),
        np.broadcast_to(world.wall_rgb, (cam.width, 3)),
        people.color_mean_rgb[ip] if n_people else np.zeros((cam.width, 3)),
    ])
    exposure = 1.0 + cam.exposure_sigma * float(rng.standard_normal())
    n_col = cam.width
    table = np.empty((7, n_col, 3))  # per column: 4 groups, floor, ceiling, handle
    table[:4] = base * (gain * shade)[..., None]
    table[4] = world.floor_rgb
    table[5] = world.ceiling_rgb
    table[6] = doors.handle_rgb[il] if doors.count else 0.0
    table = np.clip(np.rint(table * exposure), 0, 255).astype(np.uint8)
    # Rows seeing heights [lo, hi] at depth z: v ∈ [c_y + f_y (z_cam − hi)/z, c_y + f_y (z_cam − lo)/z].
    finite = np.isfinite(depth)
    with np.errstate(divide="ignore", invalid="ignore"):
        v_top = np.where(finite, cam.cy + cam.fy * (cam.mount_z_m - hi) / depth, np.inf)
        v_bottom = np.where(finite, cam.cy + cam.fy * (cam.mount_z_m - lo) / depth, -np.inf)
    rows = np.arange(cam.height, dtype=np.float64)[:, None]
    group = np.where(rows > cam.cy, np.int8(4), np.int8(5)) * np.ones((1, n_col), dtype=np.int8)
    # Painter's algorithm per column: farthest group first; on equal depth the lower group index wins.
    order = 3 - np.argsort(-depth[::-1], axis=0, kind="stable")
    col_index = np.arange(n_col)
    for rank in range(4):
        g = order[rank]
        inside = (rows >= v_top[g, col_index]) & (rows <= v_bottom[g, col_index])
        group = np.where(inside, g.astype(np.int8), group)
    if doors.count:
        along = np.hypot(*(hits[1] - doors.hinge_xy[il]).T)
        centre = doors.length_m[il] - doors.handle_from_free_end_m[il]
        in_width = doors.has_handle[il] & (np.abs(along - centre) <= doors.handle_size_m[il, 0] / 2) & finite[1]
        half = doors.handle_size_m[il, 1] / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            h_top = cam.cy + cam.fy * (cam.mount_z_m - doors.handle_height_m[il] - half) / t_l
            h_bottom = cam.cy + cam.fy * (cam.mount_z_m - doors.handle_height_m[il] + half) / t_l
        handle = (group == 1) & in_width & (rows >= h_top) & (rows <= h_bottom)
        group = np.where(handle, np.int8(6), group)
    pixels = table[group, col_index]
    if cam.noise_sigma > 0.0:
        noisy = pixels + cam.noise_sigma * rng.standard_normal(pixels.shape)
        pixels = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
    front = (i_l >= 0) & (t_l < t_s) & (t_l < t_p)
    return CameraFrame(pixels, np.where(front, i_l, -1))


# --------------------------------------------------------------------------------------------- detections


@dataclass(frozen=True)
class Box:
    """A ground-truth box in pixels (centre and size, clipped to the image) of a door leaf or its handle."""

    class_id: str  # "door" or "handle"
    door: int
    center_x: float
    center_y: float
    size_x: float
    size_y: float
    visible_fraction: float


def _clip_to_near(x0: FloatArray, z0: FloatArray, x1: FloatArray, z1: FloatArray
                  ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, npt.NDArray[np.bool_]]:
    """Clip camera-frame segments (x, z) to z ≥ NEAR_PLANE_M; the mask says which keep a part."""
    keep = (z0 >= NEAR_PLANE_M) | (z1 >= NEAR_PLANE_M)
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (NEAR_PLANE_M - z0) / (z1 - z0)
    cut0 = z0 < NEAR_PLANE_M
    cut1 = z1 < NEAR_PLANE_M
    nx0 = np.where(cut0, x0 + f * (x1 - x0), x0)
    nz0 = np.where(cut0, NEAR_PLANE_M, z0)
    nx1 = np.where(cut1, x0 + f * (x1 - x0), x1)
    nz1 = np.where(cut1, NEAR_PLANE_M, z1)
    # segments entirely behind the near plane get a harmless placeholder (masked out by ``keep``)
    return (np.where(keep, nx0, 0.0), np.where(keep, nz0, 1.0), np.where(keep, nx1, 0.0), np.where(keep, nz1, 1.0),
            keep)


def _project_boxes(cam: CameraModel, x0: FloatArray, z0: FloatArray, x1: FloatArray, z1: FloatArray,
                   h_lo: FloatArray, h_hi: FloatArray) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Image boxes (N, 4) [u_min, v_min, u_max, v_max] of vertical rectangles between two camera-frame points
    and two heights, clipped to the image ([−0.5, W − 0.5] × [−0.5, H − 0.5]); the mask says non-empty."""
    us = np.stack([cam.fx * x0 / z0 + cam.cx, cam.fx * x1 / z1 + cam.cx])
    vs = np.stack([cam.fy * (cam.mount_z_m - h) / z + cam.cy for h in (h_lo, h_hi) for z in (z0, z1)])
    box = np.stack([us.min(axis=0), vs.min(axis=0), us.max(axis=0), vs.max(axis=0)], axis=1)
    lo = np.array([-0.5, -0.5, -0.5, -0.5])
    hi = np.array([cam.width - 0.5, cam.height - 0.5, cam.width - 0.5, cam.height - 0.5])
    box = np.clip(box, lo, hi)
    return box, (box[:, 2] > box[:, 0]) & (box[:, 3] > box[:, 1])


def door_boxes(pose: FloatArray, scene: Scene, world: World, cam: CameraModel, frame: CameraFrame,
               min_visible_fraction: float) -> list[Box]:
    """Ground-truth boxes of the visible door leaves and their handles.

    A leaf's box is the bounding box of its projected rectangle (floor to door height, clipped to the near
    plane and to the image: leaves cut by the border are kept). A leaf is visible when, of the points along
    it that fall into the image, at least ``min_visible_fraction`` lie in columns where it is the front-most
    surface. A handle's box is emitted with its visible leaf when the handle's column shows that leaf.
    """
    doors = world.doors
    if doors.count == 0:
        return []
    position, heading = camera_pose(pose, cam)
    xa, za = to_camera(scene.leaves[:, 0], position, heading)
    xb, zb = to_camera(scene.leaves[:, 1], position, heading)
    x0, z0, x1, z1, keep = _clip_to_near(xa, za, xb, zb)
    box, nonempty = _project_boxes(cam, x0, z0, x1, z1, np.zeros(doors.count), doors.height_m)
    f = np.linspace(0.02, 0.98, _VISIBILITY_SAMPLES)
    xs = x0[:, None] + f * (x1 - x0)[:, None]
    zs = z0[:, None] + f * (z1 - z0)[:, None]
    col = np.rint(cam.fx * xs / zs + cam.cx)
    in_image = (col >= 0) & (col < cam.width)
    shows = np.where(in_image, frame.visible_door[np.clip(col, 0, cam.width - 1).astype(np.int64)], -1)
    n_in = in_image.sum(axis=1)
    fraction = (shows == np.arange(doors.count)[:, None]).sum(axis=1) / np.maximum(n_in, 1)
    visible = keep & nonempty & (n_in > 0) & (fraction >= min_visible_fraction)
    # handles: the rectangle on the leaf line around s_h = L − from_free_end, width w, at handle height
    leaf_dir = (scene.leaves[:, 1] - scene.leaves[:, 0]) / doors.length_m[:, None]
    s_h = doors.length_m - doors.handle_from_free_end_m
    half = doors.handle_size_m[:, 0] / 2
    ha = scene.leaves[:, 0] + (s_h - half)[:, None] * leaf_dir
    hb = scene.leaves[:, 0] + (s_h + half)[:, None] * leaf_dir
    hc = scene.leaves[:, 0] + s_h[:, None] * leaf_dir
    hxa, hza = to_camera(ha, position, heading)
    hxb, hzb = to_camera(hb, position, heading)
    hxc, hzc = to_camera(hc, position, heading)
    hbox, h_nonempty = _project_boxes(cam, hxa, np.maximum(hza, NEAR_PLANE_M), hxb, np.maximum(hzb, NEAR_PLANE_M),
                                      doors.handle_height_m - doors.handle_size_m[:, 1] / 2,
                                      doors.handle_height_m + doors.handle_size_m[:, 1] / 2)
    hcol = np.rint(cam.fx * hxc / np.maximum(hzc, NEAR_PLANE_M) + cam.cx)
    h_in = (hcol >= 0) & (hcol < cam.width)
    h_shows = np.where(h_in, frame.visible_door[np.clip(hcol, 0, cam.width - 1).astype(np.int64)], -1)
    h_visible = (visible & doors.has_handle & (hza > NEAR_PLANE_M) & (hzb > NEAR_PLANE_M) & h_nonempty
                 & (h_shows == np.arange(doors.count)))
    boxes: list[Box] = []
    for d in np.nonzero(visible)[0]:
        b = box[d]
        boxes.append(Box("door", int(d), (b[0] + b[2]) / 2, (b[1] + b[3]) / 2, b[2] - b[0], b[3] - b[1],
                         float(fraction[d])))
        if h_visible[d]:
            hb_ = hbox[d]
            boxes.append(Box("handle", int(d), (hb_[0] + hb_[2]) / 2, (hb_[1] + hb_[3]) / 2, hb_[2] - hb_[0],
                             hb_[3] - hb_[1], 1.0))
    return boxes


def noisy_detections(boxes: list[Box], spec: DetectionsSpec, cam: CameraModel, rng: np.random.Generator
                     ) -> list[tuple[str, float, float, float, float, float]]:
    """Detector output from ground-truth boxes: (class_id, score, cx, cy, w, h) with centre noise
    N(0, center_sigma_px²), size noise N(0, size_sigma_px²) (sizes ≥ 1 px), misses with ``miss_prob``,
    a score ~ U(score_min, 1), and Poisson(false_positive_rate) random false door boxes."""
    out: list[tuple[str, float, float, float, float, float]] = []
    if boxes:
        n = len(boxes)
        eps = rng.standard_normal((n, 4))
        u_miss, u_score = rng.random((2, n))
        for i, b in enumerate(boxes):
            if u_miss[i] < spec.miss_prob:
                continue
            score = spec.score_min + (1.0 - spec.score_min) * float(u_score[i])
            out.append((b.class_id, score, b.center_x + spec.center_sigma_px * float(eps[i, 0]),
                        b.center_y + spec.center_sigma_px * float(eps[i, 1]),
                        max(1.0, b.size_x + spec.size_sigma_px * float(eps[i, 2])),
                        max(1.0, b.size_y + spec.size_sigma_px * float(eps[i, 3]))))
    for _ in range(int(rng.poisson(spec.false_positive_rate))):
        u = rng.random(5)
        w = 10.0 + u[0] * cam.width / 3
        h = 20.0 + u[1] * cam.height * 0.7
        out.append(("door", spec.score_min + (1.0 - spec.score_min) * float(u[2]) * 0.5,
                    float(u[3]) * cam.width, float(u[4]) * cam.height, w, h))
    return out
