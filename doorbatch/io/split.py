"""Cut a time window out of a log into a new log (e.g. one pass of a multi-pass recording)."""

from __future__ import annotations

from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.io.log_writer import LogFormat, LogWriter
from doorbatch.io.qos import is_latched
from doorbatch.io.reader import RawMessage, open_log

# Topics whose last message before the window is still in force inside it, besides those the log records as
# latched (:func:`~doorbatch.io.qos.is_latched`): a camera's calibration is published over and over in ROS 1.
HELD_TOPICS = ("/tf_static", "/camera/camera_info")


def copy_window(source: Path, output: Path, start_ns: int, stop_ns: int, fmt: LogFormat = LogFormat.MCAP,
                config: DoorbatchConfig | None = None) -> int:
    """Copy the messages with log time in [start_ns, stop_ns) into ``output``; the latest latched message
    before the window (static TF, camera info, any topic the log records as latched) is copied too, stamped at
    ``start_ns``. The copy keeps the QoS the log records. Returns the count."""
    latched: dict[str, RawMessage] = {}
    written = 0
    with open_log(source, config) as reader, LogWriter(output, fmt) as writer:
        writer.keep_offered_qos(reader.offered_qos)
        held = set(HELD_TOPICS) | {t for t, offered in reader.offered_qos.items() if is_latched(offered)}
        for raw in reader.raw_messages():
            if raw.log_time_ns < start_ns:
                if raw.topic in held:
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
