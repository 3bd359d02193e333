"""Logs cut into passes by time (``mapping.pass_duration_s``; DESIGN: "a config option may split a long log into
passes by time").

Paper 000 maps doors from passes within which they stand still and between which they move. A robot that patrols a
floor for an hour in one recording, while people open and close doors, gives one log: as one pass, a door seen at
several angles in it is not told apart from a person, and its leaf is integrated wherever it stood. Cut into passes of
a fixed duration, each piece is such a pass, and the pieces chain as one odometry frame (they are one recording).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from doorbatch.io.recording import Recording


def pass_bounds(stamps_ns: npt.NDArray[np.int64], pass_s: float) -> list[tuple[int, int]]:
    """[start, stop) scan indices of consecutive windows of ``pass_s`` seconds from the first scan (windows
    without scans give no pass); where the log ends less than half a window into its last window, that piece
    joins the one of the window before (a few seconds of a pass would show its doors at few angles), so no pass
    spans more than 1.5 ``pass_s``. ``pass_s`` 0: one pass."""
    n = int(stamps_ns.shape[0])
    if pass_s <= 0.0 or n == 0:
        return [(0, n)]
    step_ns = max(round(pass_s * 1e9), 1)
    window = ((stamps_ns - stamps_ns[0]) // step_ns).astype(np.int64)
    starts = [0, *(np.flatnonzero(np.diff(window)) + 1).tolist()]
    bounds = list(zip(starts, [*starts[1:], n], strict=True))
    last = int(window[-1])
    into_last_s = (int(stamps_ns[-1]) - int(stamps_ns[0]) - last * step_ns) / 1e9
    if len(bounds) > 1 and into_last_s < pass_s / 2.0 and int(window[bounds[-2][0]]) == last - 1:
        bounds[-2:] = [(bounds[-2][0], n)]
    return bounds


def split_into_passes(recordings: Sequence[Recording], pass_s: float) -> list[Recording]:
    """Each recording cut into its passes (:func:`pass_bounds`), in order; a piece is named after its log and its
    span from the log's first scan (``run.mcap [0.0–60.0 s]``; :meth:`~doorbatch.io.recording.Recording.take`).
    A recording that is one pass stays as it is."""
    out: list[Recording] = []
    for rec in recordings:
        bounds = pass_bounds(rec.scans.stamps_ns, pass_s)
        if len(bounds) == 1:
            out.append(rec)
            continue
        t = (rec.scans.stamps_ns - rec.scans.stamps_ns[0]) / 1e9
        out += [rec.take(start, stop, f"{rec.path} [{t[start]:.1f}–{t[stop - 1]:.1f} s]", k)
                for k, (start, stop) in enumerate(bounds)]
    return out
