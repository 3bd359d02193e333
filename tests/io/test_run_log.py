"""OUT/run.log's handler: one JSON line per record; a disk that fills up is said once."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from doorbatch.io.run_log import JsonLinesHandler


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full (a device that is always full)")
def test_a_full_disk_is_said_once_not_per_record(capsys: pytest.CaptureFixture[str]) -> None:
    """Writes to /dev/full fail with ENOSPC: the handler says so once on stderr and drops the later records
    (logging's default printed a traceback per record: 211 lines in one cron mail)."""
    handler = JsonLinesHandler(Path("/dev/full"))
    logger = logging.getLogger("doorbatch.test_full_disk")
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        for k in range(5):
            logger.info("event %d", k)
    finally:
        logger.removeHandler(handler)
        handler.close()
    err = capsys.readouterr().err
    assert err.count("cannot write /dev/full") == 1 and "Traceback" not in err and "Logging error" not in err
