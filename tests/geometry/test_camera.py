"""Pinhole camera: projection and pixel rays on known geometry, distortion round trips, laser points via TF."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.errors import LogContentError
from doorbatch.geometry.camera import (
    box_edge_bearings,
    camera_from_info,
    in_image,
    level_rotation,
    pixel_rays,
    point_bearings,
    project_points,
    scan_in_camera,
)
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.records import CameraInfo, Scan, Transform

K = np.array([[400.0, 0.0, 319.5], [0.0, 410.0, 239.5], [0.0, 0.0, 1.0]])
PLUMB_BOB = np.array([-0.28, 0.07, 0.001, -0.0005, 0.0])


def _info(d: np.ndarray | None = None, model: str = "plumb_bob") -> CameraInfo:
    d = np.zeros(5) if d is None else d
    p = np.zeros((3, 4))
    p[:, :3] = K
    return CameraInfo(0, 0, "camera_optical", 640, 480, model, d, K, p)


def test_projection_without_distortion_is_the_pinhole_formula() -> None:
    cam = camera_from_info(_info())
    px = project_points(cam, [[1.0, 0.5, 2.0], [0.0, 0.0, 5.0], [-0.4, -0.2, 1.0]])
    np.testing.assert_allclose(px, [[319.5 + 200.0, 239.5 + 102.5], [319.5, 239.5], [159.5, 157.5]], atol=1e-9)


def test_points_behind_the_camera_project_to_nan() -> None:
    cam = camera_from_info(_info(PLUMB_BOB))
    px = project_points(cam, [[0.0, 0.0, -1.0], [0.1, 0.0, 0.0], [0.1, 0.1, 1.0], [np.nan, 0.0, 1.0]])
    assert np.isnan(px[[0, 1, 3]]).all()
    assert np.isfinite(px[2]).all()
    assert not in_image(cam, px)[0]


def test_barrel_distortion_pulls_off_axis_points_toward_the_centre() -> None:
    ideal = project_points(camera_from_info(_info()), [[0.6, 0.0, 1.0]])
    distorted = project_points(camera_from_info(_info(PLUMB_BOB)), [[0.6, 0.0, 1.0]])
    x = 0.6
    r2 = x * x
    radial = 1 + PLUMB_BOB[0] * r2 + PLUMB_BOB[1] * r2 * r2
    # plumb_bob: x_d = x·radial + 2 p1 x y + p2 (r² + 2x²), y = 0
    x_d = x * radial + PLUMB_BOB[3] * (r2 + 2 * x * x)
    assert distorted[0, 0] == pytest.approx(400.0 * x_d + 319.5, abs=1e-6)
    assert distorted[0, 0] < ideal[0, 0]


@settings(max_examples=40, deadline=None)
@given(st.floats(-0.5, 0.5), st.floats(-0.4, 0.4), st.floats(0.5, 20.0), st.sampled_from(["plumb_bob", "none"]))
def test_pixel_rays_invert_projection(xn: float, yn: float, depth: float, model: str) -> None:
    cam = camera_from_info(_info(PLUMB_BOB if model == "plumb_bob" else np.zeros(5), model))
    point = np.array([[xn * depth, yn * depth, depth]])
    ray = pixel_rays(cam, project_points(cam, point))
    np.testing.assert_allclose(ray[0] * depth, point[0], atol=1e-6 * depth)


def test_box_edge_bearings_known_angles() -> None:
    cam = camera_from_info(_info())
    left, right = box_edge_bearings(cam, 319.5 - 400.0 * math.tan(math.radians(20.0)), 319.5 + 400.0, 100.0, 300.0)
    assert left == pytest.approx(-math.radians(20.0), abs=1e-9) and right == pytest.approx(math.pi / 4, abs=1e-9)
    np.testing.assert_allclose(point_bearings([[1.0, 3.0, 1.0], [-2.0, 0.0, 2.0]]), [math.pi / 4, -math.pi / 4])


def test_a_box_edge_on_a_level_distorted_camera_has_the_bearing_of_the_point_it_sees() -> None:
    cam = camera_from_info(_info(PLUMB_BOB))
    points = np.array([[-1.5, 0.0, 3.0], [0.3, 0.0, 1.0], [2.0, 0.0, 4.0]])
    px = project_points(cam, points)
    for (u, v), expected in zip(px, point_bearings(points), strict=True):
        assert box_edge_bearings(cam, u, u, v, v)[0] == pytest.approx(expected, abs=1e-9)


def _camera_to_base(pitch_deg: float, yaw_deg: float = 0.0) -> np.ndarray:
    """A camera 1 m up, turned yaw_deg left and pitched pitch_deg down: optical z forward, x right, y down."""
    p, y = math.radians(pitch_deg), math.radians(yaw_deg)
    forward = np.array([math.cos(p) * math.cos(y), math.cos(p) * math.sin(y), -math.sin(p)])
    right = np.array([math.sin(y), -math.cos(y), 0.0])
    mat = np.eye(4)
    mat[:3, :3] = np.stack([right, np.cross(forward, right), forward], axis=1)
    mat[:3, 3] = (0.1, 0.0, 1.0)
    return mat


@pytest.mark.parametrize("distortion", [np.zeros(5), PLUMB_BOB])
@pytest.mark.parametrize("pitch_deg", [0.0, 15.0, 30.0])
def test_a_tilted_cameras_box_gives_the_bearings_of_the_door_edges(distortion: np.ndarray, pitch_deg: float) -> None:
    """A door 2 m high, 0.9 m wide, 2.5 m ahead and 0.4 m left of a camera pitched down (an outside tester's 15°
    camera had door widths 0.17 m off, median, at the horizon row): the box around its projection gives, in the
    level frame, the horizontal bearings of the two vertical edges."""
    cam = camera_from_info(_info(distortion))
    to_base = _camera_to_base(pitch_deg, yaw_deg=10.0)
    z = np.linspace(0.0, 2.0, 401)
    edges = [np.stack([np.full_like(z, 2.5), np.full_like(z, y), z], 1) for y in (0.85, -0.05)]  # left, right
    to_cam = np.linalg.inv(to_base)
    pixels = [project_points(cam, e @ to_cam[:3, :3].T + to_cam[:3, 3]) for e in edges]
    inside = np.concatenate(pixels)
    inside = inside[in_image(cam, inside)]
    u0, u1 = inside[:, 0].min(), inside[:, 0].max()
    v0, v1 = inside[:, 1].min(), inside[:, 1].max()
    level = level_rotation(to_base)
    left, right = box_edge_bearings(cam, u0, u1, v0, v1, level)
    truth = [math.atan2(-(0.85 - 0.0), 2.5 - 0.1) + math.radians(10.0), math.atan2(0.05, 2.4) + math.radians(10.0)]
    assert left == pytest.approx(truth[0], abs=2e-3) and right == pytest.approx(truth[1], abs=2e-3)
    if pitch_deg >= 15.0:  # the optical frame's horizon row, as before: the angular width off by 2-12 %
        naive = box_edge_bearings(cam, u0, u0, cam.cy, cam.cy)[0], box_edge_bearings(cam, u1, u1, cam.cy, cam.cy)[1]
        assert abs((naive[1] - naive[0]) - (truth[1] - truth[0])) > 0.015 * (truth[1] - truth[0])


def test_the_level_frame_of_a_level_camera_is_its_optical_frame() -> None:
    np.testing.assert_allclose(level_rotation(_camera_to_base(0.0, 35.0)), np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="vertical"):
        level_rotation(_camera_to_base(90.0))


def test_unknown_distortion_model_is_bad_input() -> None:
    with pytest.raises(LogContentError, match="distortion model"):
        camera_from_info(_info(model="kannala_weird"))


def test_scan_points_reach_the_camera_frame_through_tf() -> None:
    tf = TfBuffer()
    tf.add(Transform(0, "base_link", "laser", np.array([0.2, 0.0, 0.3]), np.array([0.0, 0.0, 0.0, 1.0]), True))
    # REP 103 optical frame of a forward-looking camera 1 m up
    tf.add(Transform(0, "base_link", "camera_optical", np.array([0.1, 0.0, 1.0]), np.array([-0.5, 0.5, -0.5, 0.5]),
                     True))
    ranges = np.array([2.0, np.nan, 1.0, np.inf], dtype=np.float32)
    scan = Scan(5, 5, "laser", 0.0, math.pi / 4, 0.1, 30.0, ranges)  # beams at 0, 45, 90, 135 deg
    pts, idx = scan_in_camera(scan, tf, "camera_optical")
    np.testing.assert_array_equal(idx, [0, 2])
    # forward 2 m: optical z = 2 + 0.2 − 0.1, y (down) = 1.0 − 0.3; left 1 m: optical x = −1
    np.testing.assert_allclose(pts, [[0.0, 0.7, 2.1], [-1.0, 0.7, 0.1]], atol=1e-12)


def test_in_image_covers_half_a_pixel_beyond_the_outer_pixel_centres() -> None:
    """Pixel centres at integer (u, v) (module docstring: column i is centred on u = i), so pixel i covers
    [i − 0.5, i + 0.5) and a W × H image covers [−0.5, W − 0.5) × [−0.5, H − 0.5)."""
    cam = camera_from_info(_info())  # 640 × 480
    px = np.array([
        [-0.3, 100.0],  # inside pixel column 0
        [639.7, 100.0],  # past the right half of column 639
        [100.0, -0.3],  # inside pixel row 0
        [100.0, 479.7],  # past the bottom half of row 479
        [-0.5, -0.5],  # the image's top-left corner is in
        [-0.7, 100.0],  # left of column 0
        [639.3, 479.3],  # inside the bottom-right pixel
        [639.5, 100.0],  # the right border is out
    ])
    np.testing.assert_array_equal(in_image(cam, px), [True, False, True, False, True, False, True, False])
