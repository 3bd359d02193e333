"""Sensors against independent computations: laser range noise (3σ), beam colors from the surface's color
model, camera boxes against a pinhole projection computed here from the published TF and intrinsics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from sim_helpers import OFFICE, short_scenario

from doorbatch.geometry.rotations import quaternion_to_matrix
from doorbatch.io.reader import open_log
from doorbatch.io.sim_truth import read_truth
from doorbatch.records import Role, Scan
from doorbatch.sim.scenario import CameraSpec, ColorsSpec, MountSpec, parse_scenario
from doorbatch.sim.sensors import (
    beam_colors,
    camera_model,
    camera_rotation_xyzw,
    door_boxes,
    laser_model,
    lighting_of,
    make_scene,
    render_camera,
    simulate_scan,
)
from doorbatch.sim.simulate import run_simulation
from doorbatch.sim.timeline import People
from doorbatch.sim.world import door_leaf_segments, load_world, parse_world

NO_PEOPLE = People((), (), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), (), np.zeros((0, 3)), np.zeros((0, 3)))


def _segment_distances(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest segment, in chunks (independent of the ray caster)."""
    out = np.empty(points.shape[0])
    a = segments[:, 0]
    e = segments[:, 1] - a
    for s in range(0, points.shape[0], 20_000):
        w = points[s:s + 20_000, None, :] - a[None]
        u = np.clip((w * e).sum(-1) / (e * e).sum(-1), 0.0, 1.0)
        out[s:s + 20_000] = np.linalg.norm(w - u[..., None] * e, axis=-1).min(axis=1)
    return out


@pytest.fixture(scope="module")
def laser_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 25 s drive along the office corridor, doors at several fixed angles, no people, laser and ground
    truth at 20 Hz (same stamps), σ = 2 cm; written as MCAP with its truth file."""
    from sim_helpers import write_scenario

    scenario = short_scenario(
        passes=[{"name": "p1", "route": "main", "dwell_s": 0.5, "doors": "partial",
                 "door_states": {"d01": "open", "d02": "closed", "d03": "random"}}],
        robot={"max_speed_mps": 1.0},
        sensors={"laser": {"rate_hz": 20.0, "sigma_m": 0.02, "dropout_prob": 0.02, "max_range_m": 12.0,
                           "mount": {"x_m": 0.25, "y_m": 0.05, "z_m": 0.3, "yaw_deg": 3.0}},
                 "ground_truth": {"rate_hz": 20.0}, "camera": {"enabled": False},
                 "detections": {"enabled": False}, "colors": {"enabled": False}},
    )
    folder = tmp_path_factory.mktemp("laser")
    path = write_scenario(folder / "scenario.yaml", scenario)
    return run_simulation(OFFICE, folder / "laser.mcap", path, seed=7, fmt="mcap").log_path


def test_scan_endpoints_lie_on_the_world_within_three_sigma(laser_log: Path) -> None:
    scans: list[Scan] = []
    truth_pose: dict[int, tuple[float, float, float]] = {}
    mount = None
    with open_log(laser_log) as reader:
        for rm in reader.messages([Role.SCAN, Role.REFERENCE, Role.TRANSFORMS]):
            rec = rm.record
            if rm.role is Role.SCAN:
                scans.append(rec)  # type: ignore[arg-type]
            elif rm.role is Role.REFERENCE:
                truth_pose[rec.stamp_ns] = (rec.x, rec.y, rec.yaw)  # type: ignore[union-attr]
            elif getattr(rec, "child", "") == "laser":
                mount = rec
    assert mount is not None and len(scans) > 400
    truth = read_truth(laser_log.with_name("laser.truth.yaml"))
    m_yaw = math.atan2(*quaternion_to_matrix(mount.rotation_xyzw)[[1, 0], 0])  # type: ignore[attr-defined]
    mx, my = mount.translation[:2]  # type: ignore[attr-defined]
    points, residual_rows = [], []
    for scan in scans:
        x, y, yaw = truth_pose[scan.stamp_ns]  # ground truth has the same stamps
        r = scan.ranges.astype(np.float64)
        ok = np.isfinite(r)
        a = scan.angles[ok] + m_yaw + yaw
        ox, oy = x + math.cos(yaw) * mx - math.sin(yaw) * my, y + math.sin(yaw) * mx + math.cos(yaw) * my
        points.append(np.stack([ox + r[ok] * np.cos(a), oy + r[ok] * np.sin(a)], axis=1))
        residual_rows.append((ox, oy, a, r[ok]))
    pts = np.concatenate(points)
    assert pts.shape[0] > 200_000  # thousands of beams, hundreds of thousands here
    leaves = door_leaf_segments_from_truth(truth, scans[0].stamp_ns)
    world = np.concatenate([truth.segments, leaves])
    sigma = truth.scenario["sensors"]["laser"]["sigma_m"]
    dist = _segment_distances(pts, world)
    within = np.mean(dist <= 3 * sigma)
    assert within >= 0.997, f"{within:.5f} of {pts.shape[0]} beams within 3σ"
    # the noise is really there and has the configured σ along the beams: exact ranges by solving each
    # beam against every segment (numpy.linalg.solve), for a subset of beams
    gen = np.random.default_rng(0)
    rows = [residual_rows[i] for i in gen.choice(len(residual_rows), 25, replace=False)]
    along = np.concatenate([(rr - _exact_ranges(np.array([px, py]), aa, world)) for px, py, aa, rr in rows])
    along = along[np.isfinite(along)]
    assert along.size > 10_000
    assert along.std() == pytest.approx(sigma, rel=0.05)
    assert abs(along.mean()) < 4 * sigma / math.sqrt(along.size)


def door_leaf_segments_from_truth(truth: object, stamp_ns: int) -> np.ndarray:
    """Leaves at their true angles, from the truth file's door table (signed angle = sign · opening)."""
    doors = truth.doors  # type: ignore[attr-defined]
    angles = truth.door_angles_at([stamp_ns])[0]  # type: ignore[attr-defined]
    out = []
    for d, angle in zip(doors, angles, strict=True):
        phi = d.closed_yaw + angle
        free = [d.hinge_x + d.length * math.cos(phi), d.hinge_y + d.length * math.sin(phi)]
        out.append([[d.hinge_x, d.hinge_y], free])
    return np.asarray(out)


def _exact_ranges(origin: np.ndarray, angles: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Batched 2×2 solves [d, a − b]·(t, u) = a − p for every beam and segment; nearest valid t."""
    d = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    a, b = segments[:, 0], segments[:, 1]
    mats = np.empty((d.shape[0], a.shape[0], 2, 2))
    mats[..., 0] = d[:, None, :]
    mats[..., 1] = (a - b)[None]
    rhs = np.broadcast_to(a - origin, (*mats.shape[:2], 2))
    singular = np.abs(np.linalg.det(mats)) < 1e-12
    mats[singular] = np.eye(2)
    sol = np.linalg.solve(mats, rhs[..., None])[..., 0]
    t, u = sol[..., 0], sol[..., 1]
    t = np.where(~singular & (t > 0) & (u >= 0) & (u <= 1), t, np.inf)
    return np.asarray(t.min(axis=1))


# --------------------------------------------------------------------------------------------- colors


def test_beam_color_of_a_door_hit_is_drawn_from_the_door_color_model() -> None:
    world = load_world(OFFICE)
    sc = short_scenario(sensors={"colors": {"sigma_rgb": 0.0, "gain_sigma": 0.0, "lighting_amplitude": 0.0}})
    laser = laser_model(sc.sensors.laser.model_copy(update={"dropout_prob": 0.0}))
    scene = make_scene(world, np.zeros(world.doors.count), NO_PEOPLE, np.zeros((0, 2)))
    gen = np.random.default_rng(3)
    rgb_by_surface: dict[int, list[np.ndarray]] = {}
    for x in np.linspace(2.0, 36.0, 120):  # along the corridor, looking both ways
        for yaw in (0.0, math.pi / 2, -math.pi / 2, math.pi):
            sample = simulate_scan(np.array([x, 0.0, yaw]), scene, laser, gen)
            _, rgb = beam_colors(sample, scene, laser, sc.sensors.colors, gen)
            valid = np.isfinite(sample.ranges)
            for s in np.unique(sample.surface[valid]):
                rgb_by_surface.setdefault(int(s), []).append(rgb[valid & (sample.surface == s)])
    n_static = world.segments.shape[0]
    checked = 0
    for d in range(world.doors.count):
        samples = rgb_by_surface.get(n_static + d)
        if samples is None:
            continue
        rgb = np.concatenate(samples).astype(np.float64)
        if rgb.shape[0] < 400:
            continue
        mean, std = world.doors.color_mean_rgb[d], world.doors.color_std_rgb[d]
        # rounding to integers adds variance 1/12 per channel
        np.testing.assert_allclose(rgb.mean(axis=0), mean, atol=4 * std.max() / math.sqrt(rgb.shape[0]) + 0.05)
        np.testing.assert_allclose(rgb.std(axis=0), np.sqrt(std**2 + 1 / 12), rtol=0.10)
        checked += 1
    assert checked >= 6
    # and a wall is not drawn from a door's model: wall beams have the wall's mean
    wall = np.concatenate(rgb_by_surface[0]).astype(np.float64)
    np.testing.assert_allclose(wall.mean(axis=0), world.segment_color_mean[0], atol=1.0)


def test_lighting_scales_the_surface_color_by_the_gain_at_the_hit_point() -> None:
    world = load_world(OFFICE)
    spec = ColorsSpec(sigma_rgb=0.0, gain_sigma=0.0, lighting_amplitude=0.2, lighting_period_m=5.0)
    flat = world.segment_color_std * 0.0
    scene = make_scene(world, np.zeros(world.doors.count), NO_PEOPLE, np.zeros((0, 2)))
    scene = type(scene)(scene.segments, scene.leaves, scene.people_xy, scene.people_radius_m, scene.surface_mean,
                        np.concatenate([flat, 0 * world.doors.color_std_rgb]))
    laser = laser_model(short_scenario().sensors.laser.model_copy(update={"dropout_prob": 0.0, "sigma_m": 0.0}))
    gen = np.random.default_rng(0)
    sample = simulate_scan(np.array([10.0, 0.0, 0.3]), scene, laser, gen)
    points, rgb = beam_colors(sample, scene, laser, spec, gen)
    ok = np.isfinite(sample.ranges)
    hit = sample.origin + sample.true_range[ok, None] * sample.directions[ok]
    expected = lighting_of(spec).gain(hit)[:, None] * scene.surface_mean[sample.surface[ok]]
    np.testing.assert_allclose(rgb[ok], np.clip(np.rint(expected), 0, 255), atol=0.5)
    assert np.all(np.isnan(points[~ok])) and np.all(rgb[~ok] == 0)


# --------------------------------------------------------------------------------------------- camera


ONE_DOOR_WORLD = {
    "name": "one_door",
    "materials": {"wall": {"mean_rgb": [200, 200, 200]}, "door": {"mean_rgb": [150, 60, 40]},
                  "handle": {"mean_rgb": [20, 20, 20]}},
    "walls": [{"points_m": [[-6.0, 2.0], [6.0, 2.0]]}, {"points_m": [[-6.0, -6.0], [6.0, -6.0]]},
              {"points_m": [[-6.0, -6.0], [-6.0, 2.0]]}, {"points_m": [[6.0, -6.0], [6.0, 2.0]]}],
    "doors": [{"name": "d01", "hinge_m": [-0.45, 2.0], "length_m": 0.9, "closed_yaw_deg": 0, "opening_sign": 1,
               "max_angle_deg": 100, "height_m": 2.0}],
}


def _optical_points(pose: tuple[float, float, float], spec: CameraSpec, world_xyz: np.ndarray) -> np.ndarray:
    """World points → optical frame with the transforms as published: base_link in the map from the pose,
    camera in base_link from the mount and the /tf_static quaternion (REP 103: z forward, x right, y down)."""
    x, y, yaw = pose
    r_wb = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    t_wb = np.array([x, y, 0.0])
    r_bc = quaternion_to_matrix(camera_rotation_xyzw(math.radians(spec.mount.yaw_deg)))
    t_bc = np.array([spec.mount.x_m, spec.mount.y_m, spec.mount.z_m])
    return ((world_xyz - t_wb) @ r_wb - t_bc) @ r_bc


@pytest.mark.parametrize(("pose", "angle_deg", "mount_yaw_deg"),
                         [((0.0, 0.0, math.pi / 2), 0.0, 0.0), ((0.8, -0.5, 1.9), 35.0, 0.0),
                          ((-0.6, 0.2, 1.2), 70.0, 10.0)])
def test_door_box_is_the_pinhole_projection_of_its_leaf(pose: tuple[float, float, float], angle_deg: float,
                                                        mount_yaw_deg: float) -> None:
    world = parse_world(ONE_DOOR_WORLD)
    spec = CameraSpec(width_px=320, height_px=240, hfov_deg=70.0, mount=MountSpec(x_m=0.15, y_m=0.02, z_m=1.1,
                                                                                  yaw_deg=mount_yaw_deg))
    cam = camera_model(spec)
    angles = np.array([math.radians(angle_deg)])
    scene = make_scene(world, angles, NO_PEOPLE, np.zeros((0, 2)))
    frame = render_camera(np.array(pose), scene, world, NO_PEOPLE, cam, lighting_of(ColorsSpec(lighting_amplitude=0.0)),
                          np.random.default_rng(0))
    boxes = door_boxes(np.array(pose), scene, world, cam, frame, 0.3)
    door = next(b for b in boxes if b.class_id == "door")
    # independent projection: K from the field of view, corners of the leaf rectangle
    fx = (spec.width_px / 2) / math.tan(math.radians(spec.hfov_deg) / 2)
    cx, cy = (spec.width_px - 1) / 2, (spec.height_px - 1) / 2
    leaf = door_leaf_segments(world.doors, angles)[0]
    corners = np.array([[*leaf[i], h] for i in (0, 1) for h in (0.0, 2.0)])
    p = _optical_points(pose, spec, corners)
    assert np.all(p[:, 2] > 0)
    u, v = fx * p[:, 0] / p[:, 2] + cx, fx * p[:, 1] / p[:, 2] + cy
    lo = np.array([max(u.min(), -0.5), max(v.min(), -0.5)])
    hi = np.array([min(u.max(), spec.width_px - 0.5), min(v.max(), spec.height_px - 0.5)])
    np.testing.assert_allclose([door.center_x, door.center_y], (lo + hi) / 2, atol=1e-6)
    np.testing.assert_allclose([door.size_x, door.size_y], hi - lo, atol=1e-6)
    # and the leaf is what the image shows there: the door's colour (flat-shaded) at the box centre
    px = frame.image[round(door.center_y), round(door.center_x)].astype(np.float64)
    colour = world.doors.color_mean_rgb[0]
    assert np.allclose(px / colour, px[0] / colour[0], atol=0.02), "door colour up to the shading factor"
    assert 0.5 <= px[0] / colour[0] <= 1.06
    handle = [b for b in boxes if b.class_id == "handle"]
    assert len(handle) == 1
    assert door.center_x - door.size_x / 2 <= handle[0].center_x <= door.center_x + door.size_x / 2


def test_camera_tf_is_rep103_optical() -> None:
    r = quaternion_to_matrix(camera_rotation_xyzw(0.0))
    np.testing.assert_allclose(r @ [0, 0, 1], [1, 0, 0], atol=1e-12)  # optical z = forward
    np.testing.assert_allclose(r @ [1, 0, 0], [0, -1, 0], atol=1e-12)  # optical x = right
    np.testing.assert_allclose(r @ [0, 1, 0], [0, 0, -1], atol=1e-12)  # optical y = down


def test_scan_noise_dropouts_and_no_return_follow_the_laser_spec() -> None:
    world = load_world(OFFICE)
    sc = parse_scenario({"name": "x", "passes": [{"route": "main"}],
                         "sensors": {"laser": {"dropout_prob": 0.1, "max_range_m": 8.0, "sigma_m": 0.0}}})
    laser = laser_model(sc.sensors.laser)
    scene = make_scene(world, np.zeros(world.doors.count), NO_PEOPLE, np.zeros((0, 2)))
    gen = np.random.default_rng(5)
    samples = [simulate_scan(np.array([5.0 + 0.6 * k, 0.0, 0.0]), scene, laser, gen) for k in range(50)]
    r = np.concatenate([s.ranges for s in samples])
    true = np.concatenate([s.true_range for s in samples])
    assert np.mean(np.isnan(r)) == pytest.approx(0.1, abs=0.01)
    far = true >= 8.0
    assert far.any() and np.all(np.isposinf(r[far & ~np.isnan(r)]))
    near = ~far & ~np.isnan(r)
    np.testing.assert_array_equal(r[near], true[near])
