"""doorbatch doorpose end to end: a log written with the real writers from a simulated door scene (laser,
camera_info, detector boxes, TF, ground truth), a map directory with that door, and the run directory."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from door_logs import door_log
from mcap.reader import make_reader

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.io.doorpose_inputs import read_doorpose_inputs
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.parquet import read_table, write_table
from doorbatch.io.reader import open_log
from doorbatch.maps import DoorSet
from doorbatch.pipeline.doorpose.association import associate
from doorbatch.pipeline.doorpose.run import estimate_door_poses
from doorbatch.records import Detection, Image
from doorbatch.sim.door_scene import DoorScene, DoorSceneSpec, make_door_scene
from tests.conftest import T0


def _map_dir(path: Path, scene: DoorScene) -> Path:
    d = scene.world.doors
    path.mkdir()
    write_table("doors", {
        "door_id": np.array([0, 1], dtype=np.int32),
        "hinge_x": [float(d.hinge_xy[0, 0]), 4.0], "hinge_y": [float(d.hinge_xy[0, 1]), 0.0],
        "length": [float(d.length_m[0]), 0.9], "closed_yaw": [float(d.closed_yaw_rad[0]), 0.0],
        "angle_min": [0.0, 0.0], "angle_max": [1.5, 1.5], "n_observations": np.array([3, 3], dtype=np.int32),
        "source": ["grid", "grid"], "moved": [True, True],
    }, path / "doors.parquet")
    return path


def test_doorpose_writes_door_poses_matched_to_the_map(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2 + 0.03 * k] for k in range(8)])
    log = door_log(tmp_path / "door.mcap", scene, poses, rng)
    out = tmp_path / "run"
    assert main(["doorpose", str(log), "-o", str(out), "--map", str(_map_dir(tmp_path / "map", scene)),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["paired"] == 8 and summary["frame"] == "map"
    t = read_table("door_poses", out / "door_poses.parquet").to_pydict()
    n = len(t["stamp_ns"])
    assert n == summary["door_poses"] >= 6
    assert set(t["door_id"]) == {0} and set(t["fit"]) == {"ransac"} and set(t["frame"]) == {"map"}
    np.testing.assert_allclose(t["center_x"], 0.0, atol=0.05)
    np.testing.assert_allclose(t["center_y"], 0.0, atol=0.05)
    np.testing.assert_allclose(t["yaw"], -math.pi / 2, atol=0.06)
    np.testing.assert_allclose(t["width"], scene.door_width_m, atol=0.06)
    np.testing.assert_allclose(t["goal_y"], -0.5, atol=0.06)
    np.testing.assert_allclose(t["goal_yaw"], math.pi / 2, atol=0.06)
    truth_side = scene.true_handle_side(poses[0])
    assert set(t["handle_side"]) <= {truth_side, "none"} and truth_side in t["handle_side"]
    assert abs(summary["door_angles"]["0"]) < 0.1  # the door is closed
    with (out / "annotated.mcap").open("rb") as f:
        topics = [c.topic for _, c, _ in make_reader(f).iter_messages()]
    assert topics.count("/doorbatch/door_goal") == n and topics.count("/doorbatch/door_boxes") == n
    assert topics.count("/scan") == 8  # the input is kept
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["extra"]["matched"] == n
    # the same log with another detector's label order: no door box at all, and the manifest says why
    other = tmp_path / "run_labels"
    assert main(["doorpose", str(log), "-o", str(other), "--set", "doorpose.door_class=window", "-q"]) == 0
    warnings = json.loads((other / "manifest.json").read_text())["warnings"]
    assert any("no box of class 'window'" in w and "classes seen: door" in w for w in warnings)
    assert not any("--map" in w for w in json.loads((out / "manifest.json").read_text())["warnings"])


def test_door_poses_on_the_map_hang_from_the_odometry_tree_in_the_annotations(tmp_path: Path) -> None:
    """Door poses in a reference's map frame, in a log with wheel odometry: the annotated MCAP gave them in map
    with a TF tree of odom → base_link only, so no viewer could draw them over the robot and its scans. It now
    gives map → odom at each estimate, which is where the odometry's frame lies on the map."""
    from doorbatch.io.reader import open_log

    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2 + 0.03 * k] for k in range(8)])
    offset = (1.5, -0.4, 0.3)
    log = door_log(tmp_path / "door.mcap", scene, poses, rng, map_to_odom=offset)
    out = tmp_path / "run"
    assert main(["doorpose", str(log), "-o", str(out), "-q"]) == 0
    links = []
    with open_log(out / "annotated.mcap") as reader:
        for raw in reader.raw_messages():
            if raw.topic == "/tf":
                links += [t for t in raw.msg.transforms if (t.header.frame_id, t.child_frame_id) == ("map", "odom")]
    n = len(read_table("door_poses", out / "door_poses.parquet"))
    assert n >= 6 and n - 1 <= len(links) <= n  # the last boxes come 5 ms after the last pose: none there
    for t in links:
        q = t.transform.rotation
        np.testing.assert_allclose([t.transform.translation.x, t.transform.translation.y, 2 * math.atan2(q.z, q.w)],
                                   offset, atol=1e-6)


def test_the_scan_is_moved_to_where_the_robot_was_when_the_image_was_taken(tmp_path: Path) -> None:
    """A robot turning at 1 rad/s in front of the door, its camera 40 ms after its laser: the scan's points go
    where the robot was at the image's stamp (the reference's motion between the two), and the door comes out
    where it is; taken at the scan's pose, it was turned by 0.04 rad about the robot, centimetres off."""
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(0, 0)))
    poses = np.array([[0.0, -2.4, math.pi / 2 - 0.3 + 0.2 * k] for k in range(4)])
    log = door_log(tmp_path / "turn.mcap", scene, poses, rng, box_delay_ns=35_000_000, boxes_seen_late=True)
    config = DoorbatchConfig.model_validate({"doorpose": {"fit": "lsq"}})
    found = estimate_door_poses(read_doorpose_inputs(log, config), config)
    assert len(found) >= 3
    centres = np.array([e.center for e in found.estimates])
    np.testing.assert_allclose(centres, 0.0, atol=0.02)
    np.testing.assert_allclose([e.width_m for e in found.estimates], scene.door_width_m, atol=0.03)


def test_doorpose_says_what_it_cannot_do(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Door poses of a log without a reference are not in the map's frame: matching them to --map's doors is
    said to assume one frame (62 of 135 had matched the wrong doors, silently). A log whose detection messages
    are all empty says so (it had said no message had a scan near it, and 0 images paired)."""
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2 + 0.03 * k] for k in range(4)])
    log = door_log(tmp_path / "door.mcap", scene, poses, rng)
    bare = tmp_path / "bare.mcap"
    with open_log(log) as reader, LogWriter(bare, LogFormat.MCAP) as writer:
        for raw in reader.raw_messages():
            if raw.topic == "/detections":
                raw.msg.detections = []
            if raw.topic != "/ground_truth":
                writer.write_raw(raw)
    assert main(["doorpose", str(bare), "-o", str(tmp_path / "run"), "--map", str(_map_dir(tmp_path / "map", scene)),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["paired"] == 4 and summary["frame"] == "base_link"
    warnings = json.loads((tmp_path / "run" / "manifest.json").read_text())["warnings"]
    assert any("none of 4 detection messages holds a box" in w for w in warnings)
    assert any("not in a reference's frame" in w and "--map" in w for w in warnings)
    assert not any("has a scan within" in w for w in warnings)


def test_in_a_log_with_several_cameras_the_boxes_camera_intrinsics_are_used(tmp_path: Path) -> None:
    """A RealSense log has colour, depth and infrared CameraInfo at one rate; the detections' frame names the
    camera (the infrared topic sorts last, the rule that picked it before)."""
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2 + 0.03 * k] for k in range(6)])
    log = door_log(tmp_path / "rs.mcap", scene, poses, rng, info_topic="/camera/color/camera_info",
                   other_cameras=(("/camera/infra1/camera_info", "infra1_optical", 380.0),
                                  ("/camera/depth/camera_info", "depth_optical", 390.0)))
    inputs = read_doorpose_inputs(log, DoorbatchConfig())
    np.testing.assert_allclose(inputs.camera_info.k, scene.camera_model.k)
    assert not any("CameraInfo topics" in w for w in inputs.warnings)


def test_unset_box_stamps_and_a_camera_that_is_not_level_are_reported(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2] for k in range(4)])
    unset = read_doorpose_inputs(door_log(tmp_path / "zero.mcap", scene, poses, rng, unset_box_stamps=True),
                                 DoorbatchConfig())
    assert any("4 of 4 detection messages have header stamp 0" in w for w in unset.warnings)
    found = estimate_door_poses(unset, DoorbatchConfig())
    assert found.paired == 4 and len(found) >= 3  # timed by their log time, 5 ms after their scans
    # CameraInfo's frame left as the camera body (x forward, z up), not its optical frame: z points up
    level = read_doorpose_inputs(door_log(tmp_path / "body.mcap", scene, poses, rng, camera_xyzw=(0.0, 0.0, 0.0, 1.0)),
                                 DoorbatchConfig())
    assert any("90.0 deg above the horizontal" in w for w in estimate_door_poses(level, DoorbatchConfig()).warnings)
    assert not any("horizontal" in w for w in found.warnings)


def test_a_detector_gets_the_colour_images_of_a_log_with_a_depth_camera_too(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2] for k in range(4)])
    log = door_log(tmp_path / "rgbd.mcap", scene, poses, rng, images=True, image_topic="/camera/color/image_raw",
                   depth_topic="/camera/depth/image_rect_raw", info_topic="/camera/color/camera_info",
                   other_cameras=(("/camera/depth/camera_info", "depth_optical", 380.0),))
    seen: list[str] = []
    inputs = read_doorpose_inputs(log, DoorbatchConfig(), lambda image: seen.append(image.encoding) or [])
    assert seen == ["rgb8"] * 4  # not the depth images, which no detector can use (16UC1 was exit 3)
    np.testing.assert_allclose(inputs.camera_info.k, scene.camera_model.k)  # and the colour camera's intrinsics


def test_boxes_stamped_on_publishing_take_their_images_stamp(tmp_path: Path) -> None:
    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2] for k in range(4)])
    log = door_log(tmp_path / "late.mcap", scene, poses, rng, images=True, box_delay_ns=80_000_000)
    inputs = read_doorpose_inputs(log, DoorbatchConfig())
    assert [b.stamp_ns for b in inputs.detections] == [T0 + 200_000_000 * (k + 1) + 5_000_000 for k in range(4)]
    assert any("4 of 4 detection messages carry no image's stamp" in w for w in inputs.warnings)
    images = [T0 + 200_000_000 * (k + 1) + 5_000_000 for k in range(4)]
    # 5 ms before their images (two jittering clocks): those images, not the ones 195 ms before (they were)
    early = read_doorpose_inputs(door_log(tmp_path / "early.mcap", scene, poses, rng, images=True,
                                          box_delay_ns=-5_000_000), DoorbatchConfig())
    assert [b.stamp_ns for b in early.detections] == images
    # late boxes that name the camera's body frame, not the images' optical frame: the one camera's images
    # (their publishing stamps were kept, without a word)
    body = read_doorpose_inputs(door_log(tmp_path / "body.mcap", scene, poses, rng, images=True,
                                         box_delay_ns=80_000_000, box_frame="camera_link"), DoorbatchConfig())
    assert [b.stamp_ns for b in body.detections] == images
    # a detector a whole camera period late (200 ms here) stamps its boxes with the next image's stamp: nothing in
    # the stamps tells (an outside tester's boxes 100 ms late at 10 Hz were 0.19 m off, without a word); its latency
    # given, they are its own images' again
    period_late = door_log(tmp_path / "period.mcap", scene, poses, rng, images=True, box_delay_ns=200_000_000)
    assert [b.stamp_ns for b in read_doorpose_inputs(period_late, DoorbatchConfig()).detections] == [
        *images[1:], images[-1] + 200_000_000]
    given = load_config(overrides=["doorpose.detection_time_offset_s=-0.2"])
    assert [b.stamp_ns for b in read_doorpose_inputs(period_late, given).detections] == images
    # on-time boxes in a recording that dropped every second image keep their own stamps
    sparse = read_doorpose_inputs(door_log(tmp_path / "sparse.mcap", scene, poses, rng, images=True, image_every=2),
                                  DoorbatchConfig())
    assert [b.stamp_ns for b in sparse.detections] == [T0 + 200_000_000 * (k + 1) + 5_000_000 for k in range(4)]


def test_doorpose_without_camera_info_is_bad_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(2)
    scene = make_door_scene(rng)
    log = door_log(tmp_path / "door.mcap", scene, np.array([[0.0, -2.0, math.pi / 2]]), rng)
    with open_log(log) as reader, LogWriter(tmp_path / "nocam2.mcap", LogFormat.MCAP) as writer:
        for raw in reader.raw_messages():
            if raw.topic != "/camera/camera_info":
                writer.write_raw(raw)
    assert main(["doorpose", str(tmp_path / "nocam2.mcap"), "-o", str(tmp_path / "out")]) == 3
    assert "CameraInfo" in capsys.readouterr().err


def test_simulate_approach_writes_metrics(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    exp = tmp_path / "exp.yaml"
    exp.write_text("experiment: doorpose_goal_updating\nsamples: 2\nseed: 4\nobstacles_per_scene: [0, 0]\n"
                   "config: {doorpose: {max_duration_s: 20.0}}\n")
    assert main(["doorpose", str(exp), "--simulate-approach", "-o", str(tmp_path / "sim"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert set(summary["mean_error"]) == {"initial", "continuous"}
    t = read_table("metrics", tmp_path / "sim" / "metrics.parquet").to_pydict()
    rows = dict(zip(zip(t["method"], t["metric"], strict=True), t["value"], strict=True))
    assert rows[("continuous", "samples")] == 2
    assert rows[("continuous", "positioning_error_mean")] == pytest.approx(summary["mean_error"]["continuous"])


def test_a_detector_runs_on_every_image_of_the_log(write_log: Callable[..., Path]) -> None:
    log = write_log("sample.mcap")
    seen: list[tuple[int, tuple[int, ...]]] = []

    def detector(image: Image) -> tuple[Detection, ...]:
        seen.append((image.stamp_ns, image.pixels.shape))
        return (Detection("door", 0.8, 20.0, 24.0, 10.0, 30.0),)

    inputs = read_doorpose_inputs(log, DoorbatchConfig(), detector)
    assert len(seen) == 20 and all(shape == (48, 64, 3) for _, shape in seen)
    assert [d.stamp_ns for d in inputs.detections] == [s for s, _ in seen]
    assert all(d.detections[0].center_x == 20.0 for d in inputs.detections)
    assert len(inputs.scans) == 20 and inputs.camera_info.width == 64


def test_association_reports_the_current_angle_of_the_mapped_door() -> None:
    doors = DoorSet(np.array([[0.0, 0.0], [5.0, 0.0]]), np.array([0.9, 0.9]), np.array([0.0, math.pi]),
                    np.zeros(2), np.full(2, 1.5))
    opened = 0.4  # door 0 opened 0.4 rad counter-clockwise: leaf from (0, 0) toward (0.9 cos, 0.9 sin)
    far = 0.9 * np.array([math.cos(opened), math.sin(opened)])
    match = associate(far, np.array([0.02, -0.01]), doors, 0.6)
    assert match.door_id == 0 and match.angle == pytest.approx(opened, abs=0.03)
    assert associate(np.array([2.0, 2.0]), np.array([2.9, 2.0]), doors, 0.6).door_id == -1
    closed = associate(np.array([4.1, 0.0]), np.array([5.0, 0.0]), doors, 0.6)
    assert closed.door_id == 1 and closed.angle == pytest.approx(0.0, abs=1e-9)


def test_a_tree_whose_base_is_base_footprint_gives_the_same_door_poses(tmp_path: Path) -> None:
    """The camera hangs off base_footprint and the robot's pose is odom → base_footprint (no base_link): the base
    frame is resolved as the map and localize stages resolve it, and every box still gives a door pose."""
    from doorbatch.io import ros_messages as m
    from doorbatch.sim.door_scene import DoorSceneSpec, make_door_scene

    rng = np.random.default_rng(11)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2 + 0.03 * k] for k in range(8)])
    src = door_log(tmp_path / "door.mcap", scene, poses, rng)
    log = tmp_path / "footprint.mcap"
    with open_log(src) as reader, LogWriter(log) as writer:
        k = 0
        for raw in reader.raw_messages():
            for tr in getattr(raw.msg, "transforms", []):
                if tr.header.frame_id == "base_link":
                    tr.header.frame_id = "base_footprint"
            if raw.topic == "/ground_truth":
                raw.msg.child_frame_id = "base_footprint"
                writer.write("/tf", "tf2_msgs/msg/TFMessage", raw.log_time_ns, m.tf_message(
                    [m.planar_transform(raw.log_time_ns, "odom", "base_footprint", *poses[k])]))
                k += 1
            writer.write(raw.topic, raw.msgtype, raw.log_time_ns, raw.msg, raw.store)
    counts = []
    for path in (src, log):
        assert main(["doorpose", str(path), "-o", str(tmp_path / path.stem), "-q"]) == 0
        counts.append(len(read_table("door_poses", tmp_path / path.stem / "door_poses.parquet")))
    assert counts[0] == counts[1] == len(poses)


def test_boxes_in_a_frame_nothing_defines_are_warned_of(tmp_path: Path) -> None:
    """An outside tester's boxes named zed_left_optical, a frame of no CameraInfo and not in TF: they were used as
    the one camera's without a word (right here, but with two cameras the wrong one could be taken)."""
    rng = np.random.default_rng(12)
    scene = make_door_scene(rng, DoorSceneSpec(obstacles_per_scene=(1, 1)))
    poses = np.array([[0.1 * k - 0.3, -2.6 + 0.15 * k, math.pi / 2] for k in range(3)])
    odd = read_doorpose_inputs(door_log(tmp_path / "odd.mcap", scene, poses, rng, box_frame="zed_left_optical"),
                               DoorbatchConfig())
    assert any("the boxes name frame(s) ['zed_left_optical'], which neither the CameraInfo" in w for w in odd.warnings)
    own = read_doorpose_inputs(door_log(tmp_path / "own.mcap", scene, poses, rng), DoorbatchConfig())
    assert not any("neither the CameraInfo" in w for w in own.warnings)
