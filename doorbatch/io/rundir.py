"""The run directory of ``doorbatch localize``: trajectory.parquet, door_states.parquet, trajectory.tum,
annotated.mcap (written by the caller with :mod:`doorbatch.io.annotated_mcap`), manifest.json."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, inverse
from doorbatch.io import ros_messages as rm
from doorbatch.io.annotated_mcap import Annotation
from doorbatch.io.parquet import write_table
from doorbatch.io.tum import write_tum
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.result import LocalizationResult

_LINE_LIST, _LINE_STRIP, _SPHERE_LIST = 5, 4, 7


def trajectory_columns(result: LocalizationResult) -> dict[str, object]:
    """trajectory.parquet columns (DESIGN schema)."""
    u = len(result)
    return {
        "log": [result.log] * u, "method": [result.method] * u, "stamp_ns": result.stamps_ns,
        "x": result.pose[:, 0], "y": result.pose[:, 1], "yaw": wrap_angle(result.pose[:, 2]),
        "cov_xx": result.cov[:, 0, 0], "cov_xy": result.cov[:, 0, 1], "cov_yy": result.cov[:, 1, 1],
        "cov_yaw": result.cov[:, 2, 2], "n_particles": result.n_particles.astype(np.int32),
        "neff": result.neff,
    }


def door_state_columns(result: LocalizationResult) -> dict[str, object]:
    """door_states.parquet columns (DESIGN schema): one row per update and door, in time order; with the RBPF's
    door updates while the pose was held (:attr:`~LocalizationResult.still_doors`) among them."""
    stamps, mean, std, observed = result.stamps_ns, result.door_mean, result.door_std, result.door_observed
    still = result.still_doors
    if still is not None and still.stamps_ns.size:
        order = np.argsort(np.concatenate([stamps, still.stamps_ns]), kind="stable")
        stamps = np.concatenate([stamps, still.stamps_ns])[order]
        mean, std, observed = (np.concatenate([a, b])[order] for a, b in
                               ((mean, still.mean), (std, still.std), (observed, still.observed)))
    u, d = mean.shape
    return {
        "log": [result.log] * (u * d), "method": [result.method] * (u * d),
        "stamp_ns": np.repeat(stamps, d), "door_id": np.tile(result.door_id, u),
        "angle": wrap_angle(mean.ravel()), "angle_std": std.ravel(), "observed": observed.ravel(),
    }


def write_run_tables(out: Path, result: LocalizationResult) -> list[Path]:
    """trajectory.parquet, door_states.parquet and trajectory.tum in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    write_table("trajectory", trajectory_columns(result), out / "trajectory.parquet")
    write_table("door_states", door_state_columns(result), out / "door_states.parquet")
    write_tum(out / "trajectory.tum", result.stamps_ns, result.pose[:, 0], result.pose[:, 1], result.pose[:, 2])
    return [out / "trajectory.parquet", out / "door_states.parquet", out / "trajectory.tum"]


PATH_MAX_POSES = 500  # poses in one /doorbatch/path message: the path so far, evenly thinned beyond this


def path_so_far(stamp: int, frame: str, stamps_ns: np.ndarray, poses: np.ndarray,
                max_poses: int = PATH_MAX_POSES) -> object:
    """nav_msgs/Path of the poses (K, 3) so far, thinned to at most ``max_poses`` evenly spaced ones (the first
    and the latest kept). Every message repeats the path, so without the cap an hour at 10 Hz would write some
    65 million poses (the work grows with the square of the run)."""
    k = len(stamps_ns)
    idx = np.unique(np.linspace(0, k - 1, min(k, max_poses)).round().astype(np.int64)) if k else np.zeros(0, int)
    return rm.path(stamp, frame, stamps_ns[idx], poses[idx, 0], poses[idx, 1], poses[idx, 2])


def map_to_odom_tf(stamp: int, pose: np.ndarray, odom: np.ndarray, map_frame: str, odom_frame: str) -> Annotation:
    """/tf with map→odom = pose ⊕ odom⁻¹: the transform that puts the odometry pose on the map pose."""
    map_to_odom = compose(pose, inverse(odom))
    return Annotation("/tf", "tf2_msgs/msg/TFMessage", stamp,
                      rm.tf_message([rm.planar_transform(stamp, map_frame, odom_frame, *map_to_odom)]))


def door_markers(stamp: int, frame: str, doors: DoorSet, angles: np.ndarray) -> object:
    """A MarkerArray of the doors: each leaf at ``angles`` (D,) relative to its closed direction (none where the
    angle is NaN: not known), its opening-range arc and its hinge."""
    markers = []
    ids = doors.ids.tolist()  # each marker's id is its door's doors.parquet door_id
    for k in range(len(doors)):
        hinge = doors.hinge[k]
        if np.isfinite(angles[k]):
            yaw = doors.closed_yaw[k] + angles[k]
            end = hinge + doors.length[k] * np.array([np.cos(yaw), np.sin(yaw)])
            markers.append(rm.marker(stamp, frame, "leaves", ids[k], _LINE_LIST, [tuple(hinge), tuple(end)],
                                     (0.9, 0.1, 0.1, 1.0), 0.05))
        arc = doors.closed_yaw[k] + np.linspace(doors.angle_min[k], doors.angle_max[k], 16)
        pts = hinge + doors.length[k] * np.stack([np.cos(arc), np.sin(arc)], axis=1)
        markers.append(rm.marker(stamp, frame, "ranges", ids[k], _LINE_STRIP, [tuple(p) for p in pts],
                                 (1.0, 0.6, 0.0, 0.6), 0.02))
        markers.append(rm.marker(stamp, frame, "hinges", ids[k], _SPHERE_LIST, [tuple(hinge)], (0.2, 0.2, 0.9, 1.0),
                                 0.1))
    return rm.marker_array(markers)


def run_annotations(result: LocalizationResult, occ: OccupancyMap, doors: DoorSet, map_frame: str = "map",
                    odom_frame: str = "odom", path_every: int = 10) -> Iterator[Annotation]:
    """The /doorbatch/* messages of a run in time order: the map once, then per update the pose with its
    covariance, the decimated particles, the doors at their estimated angles (an MCL run's without leaves: it
    estimates none), map→odom (against the odometry the log's TF tree holds, so that a viewer draws the robot at the
    estimate), and every ``path_every`` updates (and at the end) the path so far."""
    if not len(result):
        return
    t0 = int(result.stamps_ns[0])
    odom = result.odom if result.drawn_odom is None else result.drawn_odom  # the robot drawn from the log's TF tree
    yield Annotation("/doorbatch/map", "nav_msgs/msg/OccupancyGrid", t0,
                     rm.occupancy_grid(t0, map_frame, occ.occupancy, occ.resolution_m, occ.origin_x_m,
                                       occ.origin_y_m, occ.origin_yaw_rad))
    for i in range(len(result)):
        t = int(result.stamps_ns[i])
        x, y, yaw = (float(v) for v in result.pose[i])
        cov6 = np.zeros((6, 6))
        cov6[np.ix_([0, 1, 5], [0, 1, 5])] = result.cov[i]
        yield Annotation("/doorbatch/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", t,
                         rm.pose_with_covariance_stamped(t, map_frame, x, y, yaw, cov6))
        p = result.particles[i]
        yield Annotation("/doorbatch/particles", "geometry_msgs/msg/PoseArray", t,
                         rm.pose_array(t, map_frame, p[:, 0], p[:, 1], p[:, 2]))
        estimated = result.door_mean.shape[1] == len(doors)
        if len(doors) and (estimated or i == 0):  # MCL estimates no door: hinges and opening ranges, once (they
            # do not change; per update they had been a third of an hour's annotated.mcap, hAM)
            angles = result.door_mean[i] if estimated else np.full(len(doors), np.nan)
            yield Annotation("/doorbatch/doors", "visualization_msgs/msg/MarkerArray", t,
                             door_markers(t, map_frame, doors, angles))
        yield map_to_odom_tf(t, result.pose[i], odom[i], map_frame, odom_frame)
        if i % path_every == path_every - 1 or i == len(result) - 1:
            yield Annotation("/doorbatch/path", "nav_msgs/msg/Path", t,
                             path_so_far(t, map_frame, result.stamps_ns[: i + 1], result.pose[: i + 1]))
