"""Progress bars that appear only when stderr is a terminal (never in cron logs or CI)."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol


class Progress(Protocol):
    """What stages may call: advance by n."""

    def update(self, n: int = 1) -> object: ...


class _Silent:
    def update(self, n: int = 1) -> None:
        return None


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

    with tqdm(total=total, desc=description, unit=unit, leave=False, dynamic_ncols=True) as bar:
        yield bar
