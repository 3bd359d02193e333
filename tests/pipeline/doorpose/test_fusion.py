"""Door pose fusion (paper 003, Sec. III-B) on constructed geometry with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import DoorPoseConfig
from doorbatch.geometry.camera import camera_from_info, project_points
from doorbatch.geometry.rotations import transform_matrix
from doorbatch.pipeline.doorpose.fusion import (
    HandleSide,
    door_points,
    estimate_door,
    handle_side,
    select_door_box,
    to_planar,
)
from doorbatch.pipeline.doorpose.line_fit import LineFit
from doorbatch.records import CameraInfo, Detection
from doorbatch.sim.sensors import camera_rotation_xyzw

K = np.array([[554.0, 0.0, 319.5], [0.0, 554.0, 239.5], [0.0, 0.0, 1.0]])
CAMERA = camera_from_info(CameraInfo(0, 0, "cam", 640, 480, "plumb_bob", np.array([-0.2, 0.05, 0.0, 0.0, 0.0]),
                                     K, np.concatenate([K, np.zeros((3, 1))], axis=1)))


def _door(center_xz: tuple[float, float], yaw: float, width: float = 0.9) -> tuple[np.ndarray, np.ndarray]:
    """Edges (2, 2) of a door whose leaf runs along angle ``yaw`` in the (x, z) plane, and 40 laser points
    on it with a wall continuing on both sides (collinear: the box may overlap it)."""
    c = np.asarray(center_xz)
    d = np.array([math.cos(yaw), math.sin(yaw)])
    edges = np.stack([c - width / 2 * d, c + width / 2 * d])
    s = np.linspace(-width / 2 - 0.5, width / 2 + 0.5, 120)
    pts = c + s[:, None] * d
    return edges, np.column_stack([pts[:, 0], np.full(s.size, 0.8), pts[:, 1]])


def _box(edges_xz: np.ndarray, score: float = 0.9, cls: str = "door") -> Detection:
    px = project_points(CAMERA, [[edges_xz[0, 0], 0.0, edges_xz[0, 1]], [edges_xz[1, 0], 0.0, edges_xz[1, 1]]])
    u0, u1 = sorted(px[:, 0])
    return Detection(cls, score, (u0 + u1) / 2, 240.0, u1 - u0, 300.0)


@settings(max_examples=25, deadline=None)
@given(st.floats(-0.3, 0.3), st.floats(1.8, 4.0), st.floats(-0.5, 0.5), st.sampled_from(list(LineFit)))
def test_door_pose_is_exact_for_exact_boxes_and_points(x: float, z: float, yaw: float, fit: LineFit) -> None:
    edges, points = _door((x, z), yaw)
    door = estimate_door(CAMERA, [_box(edges)], points, DoorPoseConfig(), np.random.default_rng(0), fit)
    assert door is not None
    np.testing.assert_allclose(door.center_xz, [x, z], atol=1e-6)
    assert door.width_m == pytest.approx(0.9, abs=1e-6)
    # the normal is perpendicular to the leaf and points back to the camera at the origin
    assert abs(door.normal_xz @ [math.cos(yaw), math.sin(yaw)]) < 1e-6
    assert door.normal_xz @ door.center_xz < 0
    np.testing.assert_allclose(door.goal_xz, door.center_xz + 0.5 * door.normal_xz, atol=1e-12)


def test_box_touching_the_border_is_skipped_for_a_weaker_whole_one() -> None:
    cut = Detection("door", 0.99, 30.0, 240.0, 62.0, 300.0)  # reaches u = −1
    whole = Detection("door", 0.6, 300.0, 240.0, 100.0, 300.0)
    better = Detection("door", 0.8, 500.0, 240.0, 100.0, 300.0)
    handle = Detection("handle", 0.95, 320.0, 240.0, 10.0, 5.0)
    assert select_door_box([cut, whole, better, handle], 640, "door", 1.0) is better
    assert select_door_box([cut], 640, "door", 1.0) is None


def test_handle_side_from_the_half_of_the_door_box() -> None:
    door = Detection("door", 0.9, 300.0, 240.0, 100.0, 300.0)
    left = Detection("handle", 0.7, 265.0, 250.0, 10.0, 5.0)
    right = Detection("handle", 0.8, 340.0, 250.0, 10.0, 5.0)
    outside = Detection("handle", 0.99, 420.0, 250.0, 10.0, 5.0)
    assert handle_side(door, [door, left], "handle") is HandleSide.LEFT
    assert handle_side(door, [door, left, right, outside], "handle") is HandleSide.RIGHT
    assert handle_side(door, [door, outside], "handle") is HandleSide.NONE


def test_camera_door_to_map_through_the_mount_and_robot_pose() -> None:
    edges, points = _door((0.0, 2.0), 0.0)
    door = estimate_door(CAMERA, [_box(edges)], points, DoorPoseConfig(), np.random.default_rng(0), LineFit.LSQ)
    assert door is not None
    # optical frame 0.15 m ahead of base_link, 1.1 m up, looking along base x
    cam_to_base = transform_matrix([0.15, 0.0, 1.1], camera_rotation_xyzw(0.0))
    in_base = to_planar(door, cam_to_base)
    np.testing.assert_allclose(in_base.center, [2.15, 0.0], atol=1e-6)
    assert in_base.yaw == pytest.approx(math.pi, abs=1e-6)  # normal points back at the robot
    np.testing.assert_allclose(in_base.goal, [1.65, 0.0, 0.0], atol=1e-6)
    # the left edge (smaller optical x) is at +y in base_link
    assert in_base.left[1] == pytest.approx(0.45, abs=1e-6)
    in_map = to_planar(door, cam_to_base, np.array([1.0, 2.0, math.pi / 2]))
    np.testing.assert_allclose(in_map.center, [1.0, 4.15], atol=1e-6)
    assert in_map.yaw == pytest.approx(-math.pi / 2, abs=1e-6)
    np.testing.assert_allclose(in_map.goal, [1.0, 3.65, math.pi / 2], atol=1e-6)


def test_too_few_points_between_the_rays_give_no_estimate() -> None:
    edges, points = _door((0.0, 2.0), 0.0)
    far_right = points[points[:, 0] > 1.0]
    assert estimate_door(CAMERA, [_box(edges)], far_right, DoorPoseConfig(), np.random.default_rng(0)) is None


def test_numeric_class_ids_are_indices_into_the_label_list() -> None:
    """vision_msgs ids are indices a label map resolves (Isaac ROS publishes "0", Noetic int64 0)."""
    edges, points = _door((0.1, 2.5), 0.2)
    other, _ = _door((-0.6, 3.0), 0.0, width=0.6)  # a wrong box: a door-sized box of another class
    boxes = [_box(edges, 0.8, "1"), _box(other, 0.9, "0")]
    labels = DoorPoseConfig(class_names=["person", "door", "handle"])  # door is class 1 of this model
    door = estimate_door(CAMERA, boxes, points, labels, np.random.default_rng(0))
    assert door is not None and door.center_xz == pytest.approx([0.1, 2.5], abs=1e-6)
    numeric = DoorPoseConfig.model_validate({"door_class": 1, "handle_class": 2, "class_names": ["a", "b", "c"]})
    assert numeric.door_class == "1"  # a YAML integer names the class id
    assert estimate_door(CAMERA, boxes, points, numeric, np.random.default_rng(0)) is not None


def test_boxes_below_the_confidence_threshold_are_not_doors() -> None:
    edges, points = _door((0.1, 2.5), 0.2)
    weak, _ = _door((-0.5, 2.5), 0.0)
    boxes = [_box(weak, 0.08), _box(edges, 0.5)]  # a detector that publishes everything above 0.05
    door = estimate_door(CAMERA, boxes, points, DoorPoseConfig(), np.random.default_rng(0))
    assert door is not None and door.center_xz == pytest.approx([0.1, 2.5], abs=1e-6)
    assert estimate_door(CAMERA, boxes[:1], points, DoorPoseConfig(), np.random.default_rng(0)) is None


def test_points_on_the_cameras_vertical_axis_are_not_door_points() -> None:
    """x = z = 0 is not in front of the camera, though atan2(0, 0) = 0 puts it between any rays that
    straddle the optical axis; only the z > 0 test drops it."""
    pts = np.array([
        [0.1, 0.8, 2.0],  # in front: β = atan2(0.1, 2.0) ≈ 0.05 rad, between the rays
        [0.0, 0.5, 0.0],  # straight below the optical centre: β = atan2(0, 0) = 0
        [0.0, 0.8, -1.0],  # behind: β = π
    ])
    np.testing.assert_array_equal(door_points(pts, -0.3, 0.3), [[0.1, 2.0]])


def test_handle_above_the_door_box_gives_no_side() -> None:
    """A handle box's centre must lie in the door box in v as well as u (module docstring, step 7)."""
    door = Detection("door", 0.9, 300.0, 240.0, 100.0, 300.0)  # u ∈ [250, 350], v ∈ [90, 390]
    above = Detection("handle", 0.9, 340.0, 60.0, 10.0, 5.0)  # in the right half's columns, 30 px above
    below = Detection("handle", 0.9, 265.0, 400.0, 10.0, 5.0)  # in the left half's columns, 10 px below
    assert handle_side(door, [door, above, below], "handle") is HandleSide.NONE


def test_door_box_border_is_half_a_pixel_beyond_the_outer_pixel_centres() -> None:
    """The image spans u ∈ [−0.5, W − 0.5] (pixel centres at integers), so with a 0.5 px margin a box is
    whole when its edges lie strictly inside (0, W − 1)."""
    left_in = Detection("door", 0.9, 50.15, 240.0, 99.7, 300.0)  # u ∈ [0.3, 100.0]: 0.3 > 0
    right_cut = Detection("door", 0.95, 589.2, 240.0, 100.0, 300.0)  # u ∈ [539.2, 639.2]: 639.2 > 639
    assert select_door_box([left_in, right_cut], 640, "door", 0.5) is left_in


def test_a_door_standing_open_is_told_by_its_line_turning_from_the_wall_beside_it() -> None:
    """An outside tester's door open 35° gave a pose 0.30 m from its doorway with nothing saying so. Closed (flush in
    its wall) the door's line runs along the wall; open, the laser between the box's rays sees the leaf, turned
    from the wall beside the doorway by its opening angle."""
    edges, closed = _door((0.1, 3.0), 0.2)
    door = estimate_door(CAMERA, [_box(edges)], closed, DoorPoseConfig(), np.random.default_rng(0))
    assert door is not None and door.wall_turn_deg == pytest.approx(0.0, abs=0.5)
    d = np.array([math.cos(0.2), math.sin(0.2)])
    hinge = np.array([0.1, 3.0]) + 0.45 * d
    leaf_dir = np.array([[math.cos(math.radians(-35.0)), -math.sin(math.radians(-35.0))],
                         [math.sin(math.radians(-35.0)), math.cos(math.radians(-35.0))]]) @ -d  # toward the camera
    wall = closed[np.abs((closed[:, [0, 2]] - [0.1, 3.0]) @ d) > 0.45]
    leaf = hinge + np.linspace(0.0, 0.9, 60)[:, None] * leaf_dir
    points = np.concatenate([wall, np.column_stack([leaf[:, 0], np.full(60, 0.8), leaf[:, 1]])])
    door = estimate_door(CAMERA, [_box(edges)], points, DoorPoseConfig(), np.random.default_rng(0))
    assert door is not None and door.wall_turn_deg == pytest.approx(35.0, abs=1.0)
    assert door.wall_turn_deg > DoorPoseConfig().open_leaf_warn_deg
    # closed in a room's corner: the wall runs on at its left, and at its right the other wall turns toward the camera
    s_left = np.linspace(0.46, 0.7, 12)  # fewer points than the other wall shows
    corner = np.concatenate([np.array([0.1, 3.0]) - s_left[:, None] * d,
                             np.array([0.1, 3.0]) + np.linspace(-0.45, 0.45, 60)[:, None] * d,
                             hinge + np.linspace(0.02, 1.0, 40)[:, None] * np.array([d[1], -d[0]])])
    in_corner = np.column_stack([corner[:, 0], np.full(len(corner), 0.8), corner[:, 1]])
    door = estimate_door(CAMERA, [_box(edges)], in_corner, DoorPoseConfig(), np.random.default_rng(0))
    assert door is not None and door.wall_turn_deg < 1.0  # both sides in one fit took the other wall: 90°
