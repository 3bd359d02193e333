"""Passes recorded apart, each with its own odometry frame and no reference: each pass placed on the map of the
passes before it by global localization, so that all share the first pass's frame (``mapping.join_passes``, off by
default: without it such passes are refused as disjoint frames, issue #4).

A robot whose odometry restarts at zero with every recording (a bag per run, no localizer running) leaves one
odometry frame per pass; where a pass does not start where the one before it ended
(``mapping.odometry_continuity_m``), the passes cannot be chained. Expert choice: the pass is localized globally
(MCL, ``--init global``, the localize config) on the static map of the passes before it, and once the filter has
converged, is not ambiguous and never got lost (:mod:`.localize.convergence`), the rigid motion
T = x_u ⊕ o_u⁻¹ at the first converged update u (its map pose x_u, its odometry o_u) says where the pass's odometry
lies in the first pass's frame (:func:`join_passes` moves it so that scan matching predicts it there); scan matching
then refines every pose as in one continuous run. The first converged update
rather than a later one: T must be right where the pass starts, and the odometry drifts after. A pass that
localization cannot place is an error: a wrong motion would lay the pass across the map.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Sequence

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import PipelineError
from doorbatch.geometry.se2 import compose, inverse
from doorbatch.io.recording import Recording
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.localize.run import LocalizationMap, localize_recording
from doorbatch.pipeline.mapping import PartialMap, continues, moved_odometry

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


def join_passes(recordings: Sequence[Recording], static_map_of: Callable[[Sequence[Recording]], PartialMap],
                config: DoorbatchConfig) -> tuple[list[Recording], list[str]]:
    """The passes with the odometry of each that does not continue the previous one's moved into the first pass's
    frame (module docstring), in log order, and a note per pass localized. A pass that continues the previous one
    (:func:`~.mapping.continues`) takes its motion. ``static_map_of(passes)``: the static map the mapping stage
    builds of passes in one frame, and where their poses end; each pass is localized on the map of all passes
    before it, so that the map it is placed on is built as the final one is, in the same order.

    The mapping stage's poses go on from the previous pass's last one by odometry steps (scan matching predicts each
    scan from the last matched pose), so the odometry is moved by T' = e_o ⊕ e_m⁻¹ ⊕ T, with e_m and e_o the map
    pose and the odometry pose of the previous pass's last scan: the step from there then predicts T ⊕ o₀, where
    localization put the pass, whatever drift the matching took out of the previous pass (T' = T for odometry
    poses, where e_m = e_o). (Expert choice, measured: placing a pass on the map of whichever passes were placed
    first, or from another pass's frame, let a pass be placed 5° off on a map that chaining its passes out of log
    order had bent, and the map came out broken without an error.)

    Raises:
        PipelineError: a pass without odometry, or one that global localization does not place.
    """
    out = [recordings[0]]
    motion = np.zeros(3)
    notes = []
    for prev, nxt in itertools.pairwise(recordings):
        if not continues(prev, nxt, config):  # the next piece of one log continues it, odometry or not
            if nxt.odometry is None or prev.odometry is None:
                raise PipelineError(f"{nxt.path}: passes have disjoint coordinate frames: without a reference, "
                                    "several passes need one continuous odometry frame")
            partial = static_map_of(out)
            placed, seconds = _place(nxt, partial.occupancy, config)
            motion = compose(compose(partial.end_odometry, inverse(partial.end_pose)), placed)
            start = compose(placed, nxt.odometry.poses[0])
            notes.append(f"{nxt.path}: its odometry does not continue the previous pass's; placed on the map of the "
                         f"passes before it by global localization (MCL, converged after {seconds:.1f} s): it "
                         f"starts at ({start[0]:.3f} m, {start[1]:.3f} m, {np.degrees(start[2]):.2f}°) on that map")
            log.info(notes[-1])
        out.append(moved_odometry(nxt, motion) if motion.any() else nxt)
    return out, notes


def _place(rec: Recording, occ: OccupancyMap, config: DoorbatchConfig) -> tuple[FloatArray, float]:
    """(T, seconds to converge): the motion taking ``rec``'s odometry onto the map ``occ``, from MCL's global
    localization of ``rec`` there.

    Raises:
        PipelineError: the filter did not converge, ended ambiguous, or got lost.
    """
    result = localize_recording(rec, LocalizationMap.of(occ, DoorSet.empty(), config.localize), config, "mcl", "global")
    # lost first: without localize.relocalize_when_lost a lost run's convergence claim is withdrawn
    why = ("got lost" if result.lost_ns else "ended with several hypotheses (the map fits its scans as well at a "
           "second pose)" if result.ambiguous else "did not converge" if result.converged_ns is None else None)
    if why is not None or result.converged_ns is None:
        raise PipelineError(f"{rec.path}: passes have disjoint coordinate frames (its odometry does not continue the "
                            f"previous pass's), and global localization on the map of the passes before it {why}: "
                            "give a reference pose topic, map the logs separately, or put another log first")
    u = int(np.searchsorted(result.stamps_ns, result.converged_ns))
    motion = compose(result.pose[u], inverse(result.odom[u]))
    return motion, (result.converged_ns - int(result.stamps_ns[0])) / 1e9
