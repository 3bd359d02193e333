"""``doorbatch convert``: any supported log to MCAP (ROS 2 CDR), every message copied."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from doorbatch.config import DoorbatchConfig
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
    """Copy every message of ``source`` into ``output``; ROS 1 and Foxglove messages become ROS 2 CDR, with the
    mounts of Foxglove scans on /tf_static (:meth:`~doorbatch.io.reader.LogReader.copied_messages`); each topic keeps
    the QoS the source records (:attr:`~doorbatch.io.reader.LogReader.offered_qos`).

    Raises:
        LogReadError: the source cannot be read.
    """
    config = config or DoorbatchConfig()
    counts: dict[str, int] = {}
    with open_log(source, config) as reader:
        total = sum(t.count for t in reader.topics.values())
        with LogWriter(output, fmt) as writer, progress_bar(total, f"convert {source.name}") as bar:
            writer.keep_offered_qos(reader.offered_qos)
            for raw in reader.copied_messages():
                writer.write_raw(raw)
                counts[raw.topic] = counts.get(raw.topic, 0) + 1
                bar.update(1)
        return ConvertSummary(str(source), str(output), reader.storage, sum(counts.values()), counts,
                              list(reader.warnings))
