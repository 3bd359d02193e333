"""sensor_msgs/CameraInfo with binning and a region of interest: the intrinsics of the images as published."""

from __future__ import annotations

import numpy as np

from doorbatch.geometry.camera import camera_from_info, project_points
from doorbatch.io import ros_messages as m
from doorbatch.io.decode import decode_camera_info

K = [[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]]
POINTS = np.array([[0.3, -0.2, 2.0], [-0.5, 0.1, 3.0], [0.0, 0.0, 1.0]])


def test_binning_and_roi_map_full_resolution_intrinsics_onto_the_image() -> None:
    full = decode_camera_info(m.camera_info(0, "cam", 640, 480, K), 0)
    msg = m.camera_info(0, "cam", 640, 480, K)
    msg.binning_x = msg.binning_y = 2
    msg.roi.x_offset, msg.roi.y_offset, msg.roi.width, msg.roi.height = 100, 40, 400, 300
    cropped = decode_camera_info(msg, 0)
    assert (cropped.width, cropped.height) == (200, 150)
    # a point's pixel in the published image is its full-resolution pixel, less the offset, over the binning
    want = (project_points(camera_from_info(full), POINTS) - [100, 40]) / 2
    np.testing.assert_allclose(project_points(camera_from_info(cropped), POINTS), want, atol=1e-9)
    assert decode_camera_info(m.camera_info(0, "cam", 640, 480, K), 0).width == 640  # no binning: as it is
