"""``doorbatch convert``: any supported log to MCAP (ROS 2 CDR), every message copied."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.io import ros_messages as rm
from doorbatch.io.decode import TF_MESSAGE
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.reader import open_log
from doorbatch.progress import progress_bar


@dataclass(frozen=True)
class ConvertSummary:
    """What a conversion wrote."""

    source: str
    output: str
    storage: str
    messages: int
    topics: dict[str, int]
    warnings: list[str]


def convert_log(source: Path, output: Path, config: DoorbatchConfig | None = None,
                fmt: LogFormat = LogFormat.MCAP) -> ConvertSummary:
    """Copy every message of ``source`` into ``output``; ROS 1 messages become ROS 2 CDR.

    Raises:
        LogReadError: the source cannot be read.
    """
    config = config or DoorbatchConfig()
    counts: dict[str, int] = {}
    with open_log(source, config) as reader:
        total = sum(t.count for t in reader.topics.values())
        with LogWriter(output, fmt) as writer, progress_bar(total, f"convert {source.name}") as bar:
            mounts = list(reader.scan_origin_mounts().values())
            if mounts:  # Foxglove scans whose origin is off their frame's: the mount their frame needs
                writer.write("/tf_static", TF_MESSAGE, reader.start_ns, rm.tf_message(
                    [rm.transform_stamped(reader.start_ns, t.parent, t.child, t.translation.tolist(),
                                          t.rotation_xyzw.tolist()) for t in mounts]))
                counts["/tf_static"] = 1
            for raw in reader.raw_messages():
                writer.write_raw(raw)
                counts[raw.topic] = counts.get(raw.topic, 0) + 1
                bar.update(1)
        return ConvertSummary(str(source), str(output), reader.storage, sum(counts.values()), counts,
                              list(reader.warnings))
