"""Progress bars on a terminal (doorbatch/progress.py)."""

from __future__ import annotations

import io
import os
import re
from collections.abc import Callable
from pathlib import Path

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


def test_mapping_shows_scan_matching_and_the_grid_scan_by_scan(monkeypatch: pytest.MonkeyPatch,
                                                               write_log: Callable[..., Path]) -> None:
    """A 22-minute log sat at "map: 0/1 pass" for ten minutes of scan matching: the matcher and the grid stage now
    count scans."""
    from doorbatch.cli import main
    from tests.conftest import sample_messages

    log = write_log("scans.mcap", sample_messages(20))
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=0: os.terminal_size((100, 40)))
    assert main(["map", str(log), "-o", str(log.parent / "map"), "--pose-source", "scanmatch", "--stages",
                 "grid"]) == 0
    assert "map: scan matching" in term.getvalue() and "/19" in term.getvalue()
    assert "map: grid" in term.getvalue()


def test_localize_and_the_grid_show_how_many_scans_there_are(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """An outside tester's 50,000-particle run sat at "660scan [00:30" with no total and no time left: the bars of
    localize and of the grid stage learn the scan count once the log is read."""
    from doorbatch.cli import main
    from tests.conftest import REPO

    sample_logs = REPO / "datasets" / "sample" / "logs"
    term = _Terminal()
    monkeypatch.setattr("sys.stderr", term)
    monkeypatch.setattr(os, "get_terminal_size", lambda fd=0: os.terminal_size((100, 40)))
    log = sample_logs / "map_pass1.mcap"
    assert main(["map", str(log), "-o", str(tmp_path / "map"), "--stages", "grid"]) == 0
    assert main(["localize", str(sample_logs / "loc_open.mcap"), "--map", str(tmp_path / "map"), "-o",
                 str(tmp_path / "run"), "--method", "mcl"]) == 0
    shown = term.getvalue()
    assert "map: grid" in shown and "localize" in shown
    for name in ("map: grid", "localize: "):
        bars = [chunk for chunk in shown.split("\r") if chunk.lstrip().startswith(name)
                and not re.match(r"\s*localize: (reading|writing)", chunk)]
        assert bars and all(re.search(r"\d+/\d+ \[", b) for b in bars[1:]), bars[:3]  # "done/total [time<left"
    # what it does where it counts nothing: reading the log (23-70 s on a long one, hAM), writing annotated.mcap
    assert "localize: reading loc_open.mcap" in shown and "localize: writing annotated.mcap" in shown
