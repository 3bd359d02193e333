"""Per-beam colours from camera images (no /scan_colors): scan end points projected through CameraInfo and
TF into the image nearest in time, on a simulated log with a camera and known wall and door colours."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doorbatch.config import DoorbatchConfig
from doorbatch.io.camera_colors import _nearest_images
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.mapping import pass_poses
from doorbatch.pipeline.objectmap.beams import beams_from_scans
from doorbatch.pipeline.objectmap.stage import pass_scans
from doorbatch.sim.simulate import run_simulation

WORLD = """
name: tiny_cam
materials:
  wall: {mean_rgb: [196, 192, 182], std_rgb: [4, 4, 4]}
  door: {mean_rgb: [150, 100, 60], std_rgb: [4, 4, 4]}
  handle: {mean_rgb: [48, 48, 52], std_rgb: [3, 3, 3]}
walls:
  - {points_m: [[0.0, 1.1], [9.0, 1.1]]}
  - {points_m: [[0.0, -1.1], [9.0, -1.1]]}
  - {points_m: [[0.0, -1.1], [0.0, 1.1]]}
  - {points_m: [[9.0, -1.1], [9.0, 1.1]]}
doors:
  - {name: d01, hinge_m: [5.5, -1.1], length_m: 0.9, closed_yaw_deg: 0, opening_sign: -1, max_angle_deg: 100}
routes:
  main: {points_m: [[1.0, 0.0], [8.0, 0.0]]}
"""
SCENARIO = """
name: tiny_cam
passes:
  - {name: p1, route: main, dwell_s: 0.5, doors: closed}
sensors:
  laser: {rate_hz: 5, fov_deg: 270, beams: 270, max_range_m: 15.0, sigma_m: 0.01}
  colors: {enabled: false}
  camera: {rate_hz: 5, width_px: 160, height_px: 120, hfov_deg: 70, mount: {x_m: 0.15, z_m: 1.1}}
  detections: {enabled: false}
"""


def test_nearest_image_within_the_offset() -> None:
    images = np.array([100, 300, 200], dtype=np.int64)
    scans = np.array([90, 160, 240, 290, 500], dtype=np.int64)
    np.testing.assert_array_equal(_nearest_images(scans, images, 50), [0, 2, 2, 1, -1])


def test_beams_take_the_colour_of_what_the_camera_sees_there(tmp_path: Path) -> None:
    (tmp_path / "w.yaml").write_text(WORLD)
    (tmp_path / "s.yaml").write_text(SCENARIO)
    run_simulation(tmp_path / "w.yaml", tmp_path / "cam.mcap", scenario=str(tmp_path / "s.yaml"), seed=3)
    config = DoorbatchConfig()
    rec = load_recording(tmp_path / "cam.mcap", config, with_colors=True)
    assert rec.colors is not None and rec.color_valid is not None
    # only beams inside the camera's 70° field of view (laser and camera both look forward) get a colour
    angles = [rec.scans.angle_min[i] + rec.scans.angle_increment[i] * np.flatnonzero(v)
              for i, v in enumerate(rec.color_valid)]
    seen = np.abs(np.concatenate(angles))
    assert seen.size > 1000 and np.rad2deg(seen.max()) < 40.0
    every = config.em.model_copy(update={"still_interval_s": 0.0})
    scans = pass_scans(rec, pass_poses(rec, "reference", config), 1, every)
    beams = beams_from_scans([scans], 20.0, 1)
    pts, ok = beams.points, np.isfinite(beams.color[:, 0]) & beams.hit
    on_south = ok & (np.abs(pts[:, 1] + 1.1) < 0.05)
    door = np.median(beams.color[on_south & (pts[:, 0] > 5.6) & (pts[:, 0] < 6.3)], axis=0)
    wall = np.median(beams.color[on_south & (pts[:, 0] > 1.5) & (pts[:, 0] < 5.0)], axis=0)
    # shading scales both; the door is the brown one: red well above blue, the wall nearly grey
    assert door[0] - door[2] > 0.5 * (door[0] + door[2]) * (150 - 60) / (150 + 60)
    assert abs(wall[0] - wall[2]) < 0.1 * wall[0]
