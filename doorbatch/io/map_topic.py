"""A map from a log's nav_msgs/OccupancyGrid topic: ``doorbatch localize LOG --map RECORDED.mcap``.

A bag recorded from a Nav2 session holds the map AMCL localized on: map_server publishes it once on ``/map``
(transient local), a SLAM node republishes it as it grows. The map is the topic's *last* message (the
complete one of a growing map; the only one of map_server's). The topic is ``localize.map_topic``, else
``/map``, else the log's only OccupancyGrid topic (an annotated MCAP of doorbatch's has ``/doorbatch/map``).
Cell values outside −1..100 (a publisher's 255 for unknown, cast to int8) are unknown.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from doorbatch.errors import InputDataError, UsageError
from doorbatch.io.decode import yaw_from_quaternion
from doorbatch.io.reader import open_log
from doorbatch.maps import OCCUPIED, UNKNOWN, OccupancyMap

OCCUPANCY_GRID = "nav_msgs/msg/OccupancyGrid"
DEFAULT_MAP_TOPIC = "/map"


def read_map_topic(path: Path, topic: str | None = None) -> OccupancyMap:
    """The last nav_msgs/OccupancyGrid of ``topic`` (see the module docstring for the default) in a log.

    Raises:
        UsageError: the named topic is not an OccupancyGrid topic of the log, or no topic is named and the log
            has none or several without ``/map``.
        InputDataError: the message's data does not fill its width × height, or its resolution is not positive.
    """
    with open_log(path) as reader:
        grids = sorted(t for t, info in reader.topics.items() if info.msgtype == OCCUPANCY_GRID)
        listed = f"OccupancyGrid topics in the log: {', '.join(grids) or 'none'}"
        if topic is None:
            topic = DEFAULT_MAP_TOPIC if DEFAULT_MAP_TOPIC in grids or len(grids) != 1 else grids[0]
        if topic not in grids:
            raise UsageError(f"--map {path.name}: no map topic {topic} ({listed}; choose one with "
                             "--set localize.map_topic=TOPIC)")
        last = None
        for raw in reader.raw_messages([topic]):
            last = raw.msg
    if last is None:
        raise UsageError(f"--map {path.name}: the map topic {topic} has no message")
    info = last.info
    width, height = int(info.width), int(info.height)
    data = np.asarray(last.data).astype(np.int16)
    if data.size != width * height or data.size == 0:
        raise InputDataError(f"map topic {topic}: {data.size} cells for {width} x {height}", path=path)
    data[(data < UNKNOWN) | (data > OCCUPIED)] = UNKNOWN
    q = info.origin.orientation
    try:
        return OccupancyMap(data.astype(np.int8).reshape(height, width), float(info.resolution),
                            float(info.origin.position.x), float(info.origin.position.y),
                            yaw_from_quaternion(q.x, q.y, q.z, q.w))
    except ValueError as err:
        raise InputDataError(f"map topic {topic}: {err}", path=path) from err
