"""A global run that is lost and then found again by recovery's random particles claims the new convergence."""

from __future__ import annotations

import numpy as np
from mcl_sim import loop_trajectory, room_map, room_recording

from doorbatch.config import load_config
from doorbatch.geometry.se2 import compose, relative
from doorbatch.io.recording import Recording
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.run import LocalizationMap, localize_recording

KIDNAP = 200  # scan index (20 s at 10 Hz)


def _kidnapped() -> tuple[np.ndarray, Recording]:
    """Four laps of the room loop; at 20 s the robot is carried half a lap ahead, which its odometry never sees."""
    lap = loop_trajectory(240)
    driven = np.concatenate([lap] * 4)
    truth = driven.copy()
    truth[KIDNAP:] = np.concatenate([lap] * 5)[KIDNAP + 120 : KIDNAP + 120 + len(driven) - KIDNAP]
    steps = relative(driven[:-1], driven[1:])
    odom = np.zeros_like(driven)
    for k in range(1, len(driven)):
        odom[k] = compose(odom[k - 1], steps[k - 1])
    return truth, room_recording(truth, odom, np.random.default_rng(3))


def test_a_cloud_found_again_after_a_loss_claims_anew_and_one_never_found_does_not() -> None:
    truth, rec = _kidnapped()
    for recovery, claims in ((["localize.recovery_alpha_slow=0.001", "localize.recovery_alpha_fast=0.1"], True),
                             ([], False)):
        config = load_config(None, ["localize.seed=0", *recovery])
        lmap = LocalizationMap.of(room_map(), DoorSet.empty(), config.localize)
        result = localize_recording(rec, lmap, config, "mcl", "global")
        at = np.searchsorted(rec.scans.stamps_ns, result.stamps_ns)
        error = np.hypot(*(result.pose[:, :2] - truth[at, :2]).T)
        assert result.lost_ns and result.lost_ns[0] > rec.scans.stamps_ns[KIDNAP]
        if claims:  # found again: the claim comes after the loss, and the pose is right from it to the end
            assert result.converged_ns is not None and result.converged_ns > result.lost_ns[-1]
            assert error[result.stamps_ns >= result.converged_ns].max() < 0.1
        else:  # a cloud that drives on lost claims nothing
            assert result.converged_ns is None and error[-1] > 1.0
