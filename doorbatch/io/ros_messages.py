"""Builders of ROS 2 message objects (rosbags classes of :func:`ros2_typestore`) from plain values.

Writers, the CARMEN reader, ``convert`` and the simulator build messages only through these, so every
stamp, frame and quaternion convention lives in one place.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.io.typestore import ros2_typestore


def _t(name: str) -> Any:
    return ros2_typestore().types[name]


def time_msg(stamp_ns: int) -> Any:
    """builtin_interfaces/Time from int64 nanoseconds."""
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    return _t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(stamp_ns: int, frame_id: str) -> Any:
    """std_msgs/Header."""
    return _t("std_msgs/msg/Header")(stamp=time_msg(stamp_ns), frame_id=frame_id)


def quaternion_from_yaw(yaw: float) -> Any:
    """geometry_msgs/Quaternion of a rotation by ``yaw`` about z."""
    return _t("geometry_msgs/msg/Quaternion")(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def quaternion(xyzw: Sequence[float]) -> Any:
    """geometry_msgs/Quaternion from (x, y, z, w)."""
    x, y, z, w = (float(v) for v in xyzw)
    return _t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def vector3(x: float, y: float, z: float = 0.0) -> Any:
    """geometry_msgs/Vector3."""
    return _t("geometry_msgs/msg/Vector3")(x=float(x), y=float(y), z=float(z))


def point(x: float, y: float, z: float = 0.0) -> Any:
    """geometry_msgs/Point."""
    return _t("geometry_msgs/msg/Point")(x=float(x), y=float(y), z=float(z))


def pose(x: float, y: float, yaw: float, z: float = 0.0) -> Any:
    """geometry_msgs/Pose of a planar pose."""
    return _t("geometry_msgs/msg/Pose")(position=point(x, y, z), orientation=quaternion_from_yaw(yaw))


def laser_scan(stamp_ns: int, frame_id: str, angle_min: float, angle_increment: float,
               range_min: float, range_max: float, ranges: npt.ArrayLike,
               intensities: npt.ArrayLike | None = None, scan_time_s: float = 0.0,
               time_increment_s: float = 0.0) -> Any:
    """sensor_msgs/LaserScan; angle_max follows from the beam count. ``time_increment_s``: time between beams
    (the header stamp is the first beam's time; 0: all beams at the stamp)."""
    r = np.asarray(ranges, dtype=np.float32)
    return _t("sensor_msgs/msg/LaserScan")(
        header=header(stamp_ns, frame_id),
        angle_min=float(angle_min),
        angle_max=float(angle_min + angle_increment * (r.shape[0] - 1)),
        angle_increment=float(angle_increment),
        time_increment=float(time_increment_s),
        scan_time=float(scan_time_s),
        range_min=float(range_min),
        range_max=float(range_max),
        ranges=r,
        intensities=np.asarray(intensities if intensities is not None else [], dtype=np.float32),
    )


def odometry(stamp_ns: int, frame_id: str, child_frame_id: str, x: float, y: float, yaw: float,
             vx: float = 0.0, wz: float = 0.0, covariance: npt.ArrayLike | None = None) -> Any:
    """nav_msgs/Odometry of a planar pose and twist."""
    cov = np.zeros(36) if covariance is None else np.asarray(covariance, dtype=np.float64).reshape(36)
    return _t("nav_msgs/msg/Odometry")(
        header=header(stamp_ns, frame_id),
        child_frame_id=child_frame_id,
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(pose=pose(x, y, yaw), covariance=cov),
        twist=_t("geometry_msgs/msg/TwistWithCovariance")(
            twist=_t("geometry_msgs/msg/Twist")(linear=vector3(vx, 0.0), angular=vector3(0.0, 0.0, wz)),
            covariance=np.zeros(36),
        ),
    )


def pose_with_covariance_stamped(stamp_ns: int, frame_id: str, x: float, y: float, yaw: float,
                                 covariance: npt.ArrayLike) -> Any:
    """geometry_msgs/PoseWithCovarianceStamped (covariance 6×6 row-major, x y z roll pitch yaw)."""
    return _t("geometry_msgs/msg/PoseWithCovarianceStamped")(
        header=header(stamp_ns, frame_id),
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(
            pose=pose(x, y, yaw), covariance=np.asarray(covariance, dtype=np.float64).reshape(36)
        ),
    )


def transform_stamped(stamp_ns: int, parent: str, child: str, translation: Sequence[float],
                      rotation_xyzw: Sequence[float]) -> Any:
    """geometry_msgs/TransformStamped parent→child."""
    tx, ty, tz = (float(v) for v in translation)
    return _t("geometry_msgs/msg/TransformStamped")(
        header=header(stamp_ns, parent),
        child_frame_id=child,
        transform=_t("geometry_msgs/msg/Transform")(translation=vector3(tx, ty, tz),
                                                    rotation=quaternion(rotation_xyzw)),
    )


def planar_transform(stamp_ns: int, parent: str, child: str, x: float, y: float, yaw: float,
                     z: float = 0.0) -> Any:
    """geometry_msgs/TransformStamped of a planar pose."""
    return transform_stamped(stamp_ns, parent, child, (x, y, z),
                             (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))


def tf_message(transforms: Sequence[Any]) -> Any:
    """tf2_msgs/TFMessage of TransformStamped messages."""
    return _t("tf2_msgs/msg/TFMessage")(transforms=list(transforms))


def pose_array(stamp_ns: int, frame_id: str, x: npt.ArrayLike, y: npt.ArrayLike, yaw: npt.ArrayLike) -> Any:
    """geometry_msgs/PoseArray of planar poses."""
    poses = [pose(a, b, c) for a, b, c in zip(np.asarray(x), np.asarray(y), np.asarray(yaw), strict=True)]
    return _t("geometry_msgs/msg/PoseArray")(header=header(stamp_ns, frame_id), poses=poses)


def path(stamp_ns: int, frame_id: str, stamps_ns: npt.ArrayLike, x: npt.ArrayLike, y: npt.ArrayLike,
         yaw: npt.ArrayLike) -> Any:
    """nav_msgs/Path of planar poses."""
    ps = _t("geometry_msgs/msg/PoseStamped")
    poses = [
        ps(header=header(int(s), frame_id), pose=pose(a, b, c))
        for s, a, b, c in zip(np.asarray(stamps_ns), np.asarray(x), np.asarray(y), np.asarray(yaw), strict=True)
    ]
    return _t("nav_msgs/msg/Path")(header=header(stamp_ns, frame_id), poses=poses)


def occupancy_grid(stamp_ns: int, frame_id: str, occupancy: npt.NDArray[np.int8], resolution_m: float,
                   origin_x_m: float, origin_y_m: float, origin_yaw_rad: float = 0.0) -> Any:
    """nav_msgs/OccupancyGrid; ``occupancy`` rows go up in y (−1 unknown, 0..100)."""
    height, width = occupancy.shape
    info = _t("nav_msgs/msg/MapMetaData")(
        map_load_time=time_msg(stamp_ns), resolution=float(resolution_m), width=width, height=height,
        origin=pose(origin_x_m, origin_y_m, origin_yaw_rad),
    )
    return _t("nav_msgs/msg/OccupancyGrid")(header=header(stamp_ns, frame_id), info=info,
                                             data=np.ascontiguousarray(occupancy, dtype=np.int8).ravel())


def color_rgba(r: float, g: float, b: float, a: float = 1.0) -> Any:
    """std_msgs/ColorRGBA with components in [0, 1]."""
    return _t("std_msgs/msg/ColorRGBA")(r=float(r), g=float(g), b=float(b), a=float(a))


def marker(stamp_ns: int, frame_id: str, ns: str, marker_id: int, marker_type: int,
           points: Sequence[tuple[float, float]], rgba: tuple[float, float, float, float],
           scale_m: float = 0.05, text: str = "", position: tuple[float, float] = (0.0, 0.0)) -> Any:
    """visualization_msgs/Marker (LINE_STRIP = 4, LINE_LIST = 5, SPHERE = 2, TEXT_VIEW_FACING = 9)."""
    m = _t("visualization_msgs/msg/Marker")
    duration = _t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0)
    return m(
        header=header(stamp_ns, frame_id), ns=ns, id=int(marker_id), type=int(marker_type), action=0,
        pose=pose(position[0], position[1], 0.0), scale=vector3(scale_m, scale_m, scale_m),
        color=color_rgba(*rgba), lifetime=duration, frame_locked=False,
        points=[point(px, py) for px, py in points], colors=[], texture_resource="",
        texture=_t("sensor_msgs/msg/CompressedImage")(header=header(0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[], text=text, mesh_resource="",
        mesh_file=_t("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


def marker_array(markers: Sequence[Any]) -> Any:
    """visualization_msgs/MarkerArray."""
    return _t("visualization_msgs/msg/MarkerArray")(markers=list(markers))


def pointcloud_xyzrgb(stamp_ns: int, frame_id: str, points: npt.ArrayLike, rgb: npt.ArrayLike,
                      is_dense: bool = True) -> Any:
    """sensor_msgs/PointCloud2 with float32 x, y, z and a packed float32 ``rgb`` field (PCL layout).

    ``is_dense=False`` declares that some points are invalid (NaN), as in a cloud with one point per beam.
    """
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    col = np.asarray(rgb, dtype=np.uint8).reshape(-1, 3).astype(np.uint32)
    packed = (col[:, 0] << 16) | (col[:, 1] << 8) | col[:, 2]
    cloud = np.zeros(pts.shape[0], dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])
    cloud["x"], cloud["y"], cloud["z"], cloud["rgb"] = pts[:, 0], pts[:, 1], pts[:, 2], packed
    field = _t("sensor_msgs/msg/PointField")
    fields = [field(name=n, offset=4 * i, datatype=7, count=1) for i, n in enumerate(("x", "y", "z", "rgb"))]
    return _t("sensor_msgs/msg/PointCloud2")(
        header=header(stamp_ns, frame_id), height=1, width=pts.shape[0], fields=fields, is_bigendian=False,
        point_step=16, row_step=16 * pts.shape[0], data=np.frombuffer(cloud.tobytes(), dtype=np.uint8),
        is_dense=bool(is_dense),
    )


def image_rgb8(stamp_ns: int, frame_id: str, pixels: npt.NDArray[np.uint8]) -> Any:
    """sensor_msgs/Image, encoding rgb8 (or mono8 for a 2-D array)."""
    h, w = pixels.shape[:2]
    mono = pixels.ndim == 2
    return image(stamp_ns, frame_id, w, h, "mono8" if mono else "rgb8", w * (1 if mono else 3),
                 np.ascontiguousarray(pixels).ravel())


def image(stamp_ns: int, frame_id: str, width: int, height: int, encoding: str, step: int,
          data: npt.ArrayLike) -> Any:
    """sensor_msgs/Image of any encoding, its bytes as given (``step`` bytes per row)."""
    return _t("sensor_msgs/msg/Image")(
        header=header(stamp_ns, frame_id), height=int(height), width=int(width), encoding=encoding, is_bigendian=0,
        step=int(step), data=np.asarray(data, dtype=np.uint8).ravel(),
    )


def compressed_image(stamp_ns: int, frame_id: str, image_format: str, data: npt.ArrayLike) -> Any:
    """sensor_msgs/CompressedImage (``image_format``: jpeg, png, ...)."""
    return _t("sensor_msgs/msg/CompressedImage")(header=header(stamp_ns, frame_id), format=image_format,
                                                 data=np.asarray(data, dtype=np.uint8).ravel())


def camera_info(stamp_ns: int, frame_id: str, width: int, height: int, k: npt.ArrayLike,
                d: npt.ArrayLike = (0.0, 0.0, 0.0, 0.0, 0.0), distortion_model: str = "plumb_bob",
                p: npt.ArrayLike | None = None, r: npt.ArrayLike | None = None) -> Any:
    """sensor_msgs/CameraInfo of a pinhole camera (P = [K | 0] and R = I unless given)."""
    kk = np.asarray(k, dtype=np.float64).reshape(3, 3)
    if p is None:
        p = np.zeros((3, 4))
        p[:, :3] = kk
    p = np.asarray(p, dtype=np.float64).reshape(3, 4)
    r = np.eye(3) if r is None else np.asarray(r, dtype=np.float64).reshape(3, 3)
    roi = _t("sensor_msgs/msg/RegionOfInterest")(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return _t("sensor_msgs/msg/CameraInfo")(
        header=header(stamp_ns, frame_id), height=int(height), width=int(width),
        distortion_model=distortion_model, d=np.asarray(d, dtype=np.float64), k=kk.ravel(),
        r=r.ravel(), p=p.ravel(), binning_x=0, binning_y=0, roi=roi,
    )


def detection_array(stamp_ns: int, frame_id: str,
                    boxes: Sequence[tuple[str, float, float, float, float, float]]) -> Any:
    """vision_msgs/Detection2DArray (ROS 2 layout) of (class_id, score, cx, cy, w, h) boxes in pixels."""
    hyp, hyp_pose = _t("vision_msgs/msg/ObjectHypothesis"), _t("vision_msgs/msg/ObjectHypothesisWithPose")
    cov_pose = _t("geometry_msgs/msg/PoseWithCovariance")
    dets = []
    for i, (cls, score, cx, cy, w, h) in enumerate(boxes):
        center = _t("vision_msgs/msg/Pose2D")(position=_t("vision_msgs/msg/Point2D")(x=float(cx), y=float(cy)),
                                              theta=0.0)
        dets.append(_t("vision_msgs/msg/Detection2D")(
            header=header(stamp_ns, frame_id),
            results=[hyp_pose(hypothesis=hyp(class_id=str(cls), score=float(score)),
                              pose=cov_pose(pose=pose(0.0, 0.0, 0.0), covariance=np.zeros(36)))],
            bbox=_t("vision_msgs/msg/BoundingBox2D")(center=center, size_x=float(w), size_y=float(h)),
            id=str(i),
        ))
    return _t("vision_msgs/msg/Detection2DArray")(header=header(stamp_ns, frame_id), detections=dets)


def pose_stamped(stamp_ns: int, frame_id: str, x: float, y: float, yaw: float) -> Any:
    """geometry_msgs/PoseStamped of a planar pose."""
    return _t("geometry_msgs/msg/PoseStamped")(header=header(stamp_ns, frame_id), pose=pose(x, y, yaw))


def image_box_marker(stamp_ns: int, frame_id: str, ns: str, marker_id: int, box_uv: Sequence[float],
                     rgba: tuple[float, float, float, float], width_px: float = 2.0) -> Any:
    """visualization_msgs/ImageMarker: a closed LINE_STRIP around the pixel box (u0, v0, u1, v1)."""
    u0, v0, u1, v1 = (float(b) for b in box_uv)
    duration = _t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0)
    color = color_rgba(*rgba)
    return _t("visualization_msgs/msg/ImageMarker")(
        header=header(stamp_ns, frame_id), ns=ns, id=int(marker_id), type=1, action=0,  # 1: LINE_STRIP
        position=point(0.0, 0.0), scale=float(width_px), outline_color=color, filled=0,
        fill_color=color_rgba(0.0, 0.0, 0.0, 0.0), lifetime=duration,
        points=[point(u, v) for u, v in ((u0, v0), (u1, v0), (u1, v1), (u0, v1), (u0, v0))],
        outline_colors=[],
    )
