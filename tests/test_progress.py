"""Progress bars on a terminal (doorbatch/progress.py)."""

from __future__ import annotations

import io
import os

import pytest

from doorbatch import progress


class _Terminal(io.StringIO):
    """A stderr that is a terminal, as ``script`` or ``ssh -t`` give one: possibly one that reports no size."""

    def isatty(self) -> bool:
        return True

    def fileno(self) -> int:
        return 2


@pytest.mark.parametrize("size", [(0, 0), (100, 40)])
def test_a_bar_is_drawn_on_a_terminal_of_any_reported_size(monkeypatch: pytest.MonkeyPatch,
                                                           size: tuple[int, int]) -> None:
    """A pty opened without a size (0 × 0) drew no bar at all (a user saw none in 26 minutes of em stage): tqdm
    took 0 rows as no room. It now draws at 80 × 24 there, at the terminal's size elsewhere."""
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=0: os.terminal_size(size))
    progress.set_progress_enabled(True)
    with progress.progress_bar(None, "em stage", unit="step") as bar:
        bar.update(3)
    assert "em stage: 0step" in term.getvalue()


def test_no_bar_off_a_terminal(monkeypatch: pytest.MonkeyPatch) -> None:
    out = io.StringIO()
    monkeypatch.setattr("sys.stderr", out)
    with progress.progress_bar(10, "map") as bar:
        bar.update(1)
    assert out.getvalue() == ""
