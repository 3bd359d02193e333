"""sensor_msgs/CameraInfo with binning and a region of interest: the intrinsics of the images as published."""

from __future__ import annotations

import numpy as np
import pytest

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


def _raw_image(encoding: str, data: np.ndarray, width: int, height: int, step: int) -> object:
    msg = m.image_rgb8(0, "cam", np.zeros((height, width), np.uint8))
    msg.encoding, msg.step, msg.data = encoding, step, np.ascontiguousarray(data, dtype=np.uint8).ravel()
    return msg


def test_bayer_and_yuv422_images_decode_to_rgb() -> None:
    """8-bit Bayer (ROS bayer_rggb8: R at even rows and columns, B at odd ones) and yuv422 (UYVY) images, as
    sensor_msgs/image_encodings lays them out, decode to their colours (interior pixels, away from the edge)."""
    from doorbatch.io.decode import decode_image

    mosaic = np.full((8, 8), 60, np.uint8)  # green everywhere but the R and B sites
    mosaic[0::2, 0::2], mosaic[1::2, 1::2] = 200, 10
    rgb = decode_image(_raw_image("bayer_rggb8", mosaic, 8, 8, 8), "sensor_msgs/msg/Image", 0, "/img").pixels
    np.testing.assert_allclose(rgb[2:6, 2:6].reshape(-1, 3).mean(axis=0), [200, 60, 10], atol=3)
    grey = np.tile(np.array([128, 150, 128, 150], np.uint8), (4, 4))  # U Y V Y: colourless, Y = 150
    rgb = decode_image(_raw_image("yuv422", grey, 8, 4, 16), "sensor_msgs/msg/Image", 0, "/img").pixels
    assert rgb.shape == (4, 8, 3) and np.ptp(rgb) <= 2 and abs(int(rgb.mean()) - 150) <= 25


def test_image_data_that_does_not_fit_its_size_is_bad_input_naming_the_topic() -> None:
    from doorbatch.errors import LogContentError
    from doorbatch.io.decode import decode_image

    for encoding, data, width in (("bayer_rggb8", np.zeros(10, np.uint8), 8), ("rgb8", np.zeros(10, np.uint8), 8),
                                  ("yuv422", np.zeros(4 * 14, np.uint8), 7)):  # short buffers; an odd YUV width
        with pytest.raises(LogContentError, match="/img") as err:
            decode_image(_raw_image(encoding, data, width, 4, 2 * width if encoding == "yuv422" else width * 3),
                         "sensor_msgs/msg/Image", 0, "/img")
        assert "does not fit" in str(err.value)
