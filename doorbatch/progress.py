"""Progress bars that appear only when stderr is a terminal (never in cron logs or CI)."""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, Protocol


class Progress(Protocol):
    """What stages may call: advance by n; set the total once it is known (a log's scan count, once it is read);
    say what is being done where it is not counted (reading a long log, writing annotated.mcap)."""

    def update(self, n: int = 1) -> object: ...

    def set_total(self, total: int) -> None: ...

    def describe(self, text: str) -> None: ...


class _Silent:
    def update(self, n: int = 1) -> None:
        return None

    def set_total(self, total: int) -> None:
        return None

    def describe(self, text: str) -> None:
        return None


class _Bar:
    """A tqdm bar whose total may be set after it started (then it shows the fraction done and the time left)."""

    def __init__(self, bar: Any) -> None:
        self._bar = bar

    def update(self, n: int = 1) -> object:
        return self._bar.update(n)

    def set_total(self, total: int) -> None:
        """The total, the count and the clock started again: the time spent reading a log is no time per item (an
        ETA of 141 hours had stood while a 34 MB log was read)."""
        done = self._bar.n
        self._bar.reset(total=total)
        if done:
            self._bar.update(done)

    def describe(self, text: str) -> None:
        self._bar.set_description_str(text)


_ENABLED = True


def set_progress_enabled(enabled: bool) -> None:
    """The CLI turns bars off for ``-q`` and ``--json``."""
    global _ENABLED
    _ENABLED = enabled


@contextmanager
def progress_bar(total: int | None, description: str, unit: str = "msg") -> Iterator[Progress]:
    """A tqdm bar on a terminal, else a silent counter."""
    if not (_ENABLED and sys.stderr.isatty()):
        yield _Silent()
        return
    from tqdm import tqdm

    with tqdm(total=total, desc=description, unit=unit, leave=False, **_width()) as bar:
        yield _Bar(bar)


def _width() -> dict[str, object]:
    """tqdm's size: the terminal's, its width followed as it is resized; 80 columns and 24 rows where the terminal
    reports none (a pty that ``script``, ``ssh -t`` from a job runner or a container's ``-t`` opens without a
    size: tqdm took 0 rows for "no room" and drew nothing at all)."""
    try:
        size = os.get_terminal_size(sys.stderr.fileno())
        columns, lines = size.columns, size.lines
    except (OSError, ValueError, AttributeError):
        columns = lines = 0
    shape: dict[str, object] = {"dynamic_ncols": True} if columns > 0 else {"ncols": 80}
    if lines <= 0:
        shape["nrows"] = 24
    return shape
