"""``OUT/run.log``: one JSON object per line for every event of a ``doorbatch run`` (cron-friendly).

Each line has ``time`` (ISO 8601 UTC), ``level``, ``logger``, ``message``, and the fields a caller passes in
``extra={"event": ..., ...}`` (``event``, ``step``, ``status``, ``seconds``, ``error``...). The file is
appended to, so it keeps the history of every run into the same output folder; each run starts with a
``run_started`` event. Lines are written whole and flushed one by one.
"""

from __future__ import annotations

import contextlib
import json
import logging
import sys
from pathlib import Path
from typing import Any, TextIO

from doorbatch.io.manifest import utc_now_iso

RUN_LOG = "run.log"
SUMMARY_FILE = "summary.json"  # beside run.log: the last run's summary (pipeline.batch.run)
_STANDARD = set(vars(logging.LogRecord("", 0, "", 0, "", None, None))) | {"message", "asctime"}


def record_fields(record: logging.LogRecord) -> dict[str, Any]:
    """The JSON object of one log record: the standard fields and every ``extra`` field."""
    fields: dict[str, Any] = {"time": utc_now_iso(), "level": record.levelname, "logger": record.name,
                              "message": record.getMessage()}
    fields.update({k: v for k, v in vars(record).items() if k not in _STANDARD})
    if record.exc_info:
        fields["traceback"] = logging.Formatter().formatException(record.exc_info)
    return fields


class JsonLinesHandler(logging.Handler):
    """A logging handler appending one JSON line per record to a file."""

    def __init__(self, path: Path, level: int = logging.INFO) -> None:
        super().__init__(level)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.path = path
        self._file: TextIO = path.open("a", encoding="utf-8")
        self.failed: OSError | None = None  # the first write that failed (a full disk): said once, not per record

    def emit(self, record: logging.LogRecord) -> None:
        """Append the record as one line and flush it. A write that fails (no space left) is said once on stderr,
        and the records after it are dropped: logging's default printed a traceback per record into cron's mail."""
        if self.failed is not None:
            return
        try:
            self._file.write(json.dumps(record_fields(record), default=str) + "\n")
            self._file.flush()
        except OSError as err:
            self.failed = err
            sys.stderr.write(f"doorbatch: cannot write {self.path} ({err.strerror or err}); its later events are "
                             "lost\n")
        except Exception:
            self.handleError(record)

    def close(self) -> None:
        """Close the file (a full disk may refuse the last flush: said already)."""
        with contextlib.suppress(OSError):
            self._file.close()
        super().close()


def read_run_log(path: Path) -> list[dict[str, Any]]:
    """Every event of a run.log, in order."""
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
