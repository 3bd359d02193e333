"""The map directory of ``doorbatch map``: map.yaml + map.pgm, doors.parquet, preview.png, manifest.json, and with
``--mcap`` the messages of the mapping run's annotated.mcap (written with :mod:`doorbatch.io.annotated_mcap`)."""

from __future__ import annotations

import heapq
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.io import ros_messages as rm
from doorbatch.io.annotated_mcap import Annotation, on_log_clock
from doorbatch.io.log_clock import LogClock
from doorbatch.io.manifest import Manifest
from doorbatch.io.map_server import write_map
from doorbatch.io.parquet import read_table, write_table
from doorbatch.io.preview import PreviewDoor, render_preview, write_preview
from doorbatch.io.rundir import door_markers, map_to_odom_tf, path_so_far
from doorbatch.maps import DoorSet, OccupancyMap

FloatArray = npt.NDArray[np.float64]


def doors_columns(doors: Sequence[PreviewDoor], n_observations: Sequence[int], source: str | Sequence[str],
                  ) -> dict[str, object]:
    """doors.parquet columns (DESIGN schema), door_id in the given order, angles wrapped to (−π, π]; ``source``
    one for all rows or one per row."""
    n = len(doors)
    return {
        "door_id": np.arange(n, dtype=np.int32),
        "hinge_x": [d.hinge_x for d in doors],
        "hinge_y": [d.hinge_y for d in doors],
        "length": [d.length for d in doors],
        "closed_yaw": wrap_angle([d.closed_yaw for d in doors]) if n else [],
        "angle_min": [d.angle_min for d in doors],
        "angle_max": [d.angle_max for d in doors],
        "n_observations": np.asarray(n_observations, dtype=np.int32),
        "source": [source] * n if isinstance(source, str) else list(source),
        "moved": [d.moved for d in doors],
    }


def write_map_dir(out: Path, static_map: OccupancyMap, doors: Sequence[PreviewDoor], n_observations: Sequence[int],
                  source: str | Sequence[str], trajectories: Sequence[np.ndarray], walls: np.ndarray | None = None
                  ) -> list[Path]:
    """Write map.yaml/map.pgm, doors.parquet and preview.png (with ``walls`` (K, 2, 2) segments of the em
    stage drawn, when given) into ``out``; returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    write_map(static_map, out / "map.yaml")
    write_table("doors", doors_columns(doors, n_observations, source), out / "doors.parquet")
    write_preview(out / "preview.png", render_preview(static_map, doors, trajectories, walls=walls))
    return [out / "map.yaml", out / "map.pgm", out / "doors.parquet", out / "preview.png"]


# Pose sources whose maps lie in their first pass's odometry frame, not a reference's (world) frame.
ODOMETRY_FRAME_SOURCES = ("scanmatch", "odometry")


def manifest_pose_source(manifest: Manifest) -> str | None:
    """The pose source a map was built from, as its manifest records it, or None."""
    source = manifest.extra.get("pose_source")
    return str(source) if source is not None else None


def map_pose_source(map_path: Path) -> str | None:
    """The pose source a doorbatch map directory was built from (``manifest.json``), or None."""
    folder = map_path if map_path.is_dir() else map_path.parent
    yaml_named = map_path.suffix in (".yaml", ".yml") and map_path.is_file()  # a map YAML of any name
    if not (folder / "manifest.json").is_file() or not (yaml_named or (folder / "map.yaml").is_file()):
        return None
    return manifest_pose_source(Manifest.read(folder / "manifest.json"))


def read_door_set(map_dir: Path) -> DoorSet:
    """doors.parquet of a map directory as arrays (any source: grid or em). A map without the file has
    no doors (a plain map_server map from another SLAM tool)."""
    return read_doors_moved(map_dir)[0]


def read_doors_moved(map_dir: Path) -> tuple[DoorSet, npt.NDArray[np.bool_]]:
    """:func:`read_door_set` and, per door, doors.parquet's ``moved`` (seen at two or more distinguishable
    angles), from one read of the file; no doors without it."""
    path = map_dir / "doors.parquet"
    if not path.exists():
        return DoorSet.empty(), np.zeros(0, dtype=np.bool_)
    columns = read_table("doors", path).to_pydict()
    return door_set_of(columns), np.asarray(columns["moved"], dtype=np.bool_)


def door_set_of_previews(doors: Sequence[PreviewDoor]) -> DoorSet:
    """The doors a map directory writes (:class:`PreviewDoor`) as a DoorSet, through their doors.parquet columns."""
    return door_set_of(doors_columns(doors, [0] * len(doors), ""))


def door_set_of(t: Mapping[str, Any]) -> DoorSet:
    """doors.parquet columns (``to_pydict``) as a DoorSet."""
    return DoorSet(np.array([t["hinge_x"], t["hinge_y"]], dtype=np.float64).T.reshape(-1, 2),
                   np.asarray(t["length"], dtype=np.float64), np.asarray(t["closed_yaw"], dtype=np.float64),
                   np.asarray(t["angle_min"], dtype=np.float64), np.asarray(t["angle_max"], dtype=np.float64),
                   np.asarray(t["door_id"], dtype=np.int32))


@dataclass(frozen=True)
class MappedPass:
    """One pass of a mapping run as the annotated MCAP shows it: robot poses (map frame) at scan stamps, the
    odometry there (None: no map→odom transform), and each door's angle relative to its closed direction
    during the pass (NaN: not known, e.g. a grid-stage door, whose leaves are not kept per pass)."""

    stamps_ns: npt.NDArray[np.int64]
    poses: FloatArray
    odometry: FloatArray | None
    door_angles: FloatArray
    log_clock: LogClock | None = None  # the log's recorder clock against its scan stamps (Recording.log_clock)


def mapping_annotations(passes: Sequence[MappedPass], static_map: OccupancyMap, doors: DoorSet,
                        map_frame: str = "map", odom_frame: str = "odom", path_every: int = 10
                        ) -> Iterator[Annotation]:
    """The /doorbatch/* messages of a mapping run in time order: the static map at the first scan; per pass
    the doors (leaves at the pass's angles, opening ranges, hinges) at its first scan; per scan the robot pose
    and map→odom; every ``path_every`` scans (and at each pass's end) the pass's path so far."""
    nonempty = [p for p in passes if p.stamps_ns.size]
    if not nonempty:
        return
    logged = {id(p): p.stamps_ns[0] if p.log_clock is None else p.log_clock.log_time_at(int(p.stamps_ns[0]))
              for p in nonempty}
    first = min(nonempty, key=lambda p: int(logged[id(p)]))
    t0 = int(first.stamps_ns[0])
    yield Annotation("/doorbatch/map", "nav_msgs/msg/OccupancyGrid", int(logged[id(first)]),
                     rm.occupancy_grid(t0, map_frame, static_map.occupancy, static_map.resolution_m,
                                       static_map.origin_x_m, static_map.origin_y_m, static_map.origin_yaw_rad))
    # passes in time order, merged by time should two of them overlap (logs that each restart a simulated clock)
    yield from heapq.merge(*(on_log_clock(_pass_annotations(p, doors, map_frame, odom_frame, path_every),
                                          p.log_clock) for p in passes),
                           key=lambda a: a.log_time_ns)


def _pass_annotations(mapped: MappedPass, doors: DoorSet, map_frame: str, odom_frame: str, path_every: int
                      ) -> Iterator[Annotation]:
    """One pass's messages of :func:`mapping_annotations`, in time order."""
    n = mapped.stamps_ns.size
    for i in range(n):
        t = int(mapped.stamps_ns[i])
        if i == 0 and len(doors):
            yield Annotation("/doorbatch/doors", "visualization_msgs/msg/MarkerArray", t,
                             door_markers(t, map_frame, doors, mapped.door_angles))
        x, y, yaw = (float(v) for v in mapped.poses[i])
        yield Annotation("/doorbatch/pose", "geometry_msgs/msg/PoseWithCovarianceStamped", t,
                         rm.pose_with_covariance_stamped(t, map_frame, x, y, yaw, np.zeros((6, 6))))
        if mapped.odometry is not None:
            yield map_to_odom_tf(t, mapped.poses[i], mapped.odometry[i], map_frame, odom_frame)
        if i % path_every == path_every - 1 or i == n - 1:
            yield Annotation("/doorbatch/path", "nav_msgs/msg/Path", t,
                             path_so_far(t, map_frame, mapped.stamps_ns[: i + 1], mapped.poses[: i + 1]))
