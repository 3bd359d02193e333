"""Cut a time window out of a log into a new log (e.g. one pass of a multi-pass recording)."""

from __future__ import annotations

from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.reader import RawMessage, open_log

# Topics whose last message before the window is still in force inside it (latched in ROS).
LATCHED_TOPICS = ("/tf_static", "/camera/camera_info")


def copy_window(source: Path, output: Path, start_ns: int, stop_ns: int, fmt: LogFormat = LogFormat.MCAP,
                config: DoorbatchConfig | None = None) -> int:
    """Copy the messages with log time in [start_ns, stop_ns) into ``output``; the latest latched message
    before the window (static TF, camera info) is copied too, stamped at ``start_ns``. Returns the count."""
    latched: dict[str, RawMessage] = {}
    written = 0
    with open_log(source, config) as reader, LogWriter(output, fmt) as writer:
        for raw in reader.raw_messages():
            if raw.log_time_ns < start_ns:
                if raw.topic in LATCHED_TOPICS:
                    latched[raw.topic] = raw
                continue
            if raw.log_time_ns >= stop_ns:
                break
            for topic in list(latched):
                old = latched.pop(topic)
                writer.write_raw(RawMessage(old.topic, old.msgtype, start_ns, old.msg, old.ros1, old.store))
                written += 1
            writer.write_raw(raw)
            written += 1
    return written
