"""``global_success``: the convergence window and the pose thresholds, on a robot standing still."""

from __future__ import annotations

import numpy as np
import pytest

from doorbatch.pipeline.evaluate.localization_success import ConvergenceCheck, global_success

T0 = 1_700_000_000_000_000_000
S = 1_000_000_000
CHECK = ConvergenceCheck(window_s=10.0, max_xy_m=0.5, max_yaw_rad=0.2, max_reference_gap_s=1.5)


def _run(n_s: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """One estimate per second for ``n_s`` s, every one at the reference pose (2, 3, 0.5)."""
    stamps = T0 + S * np.arange(n_s + 1, dtype=np.int64)
    return stamps, np.tile([2.0, 3.0, 0.5], (n_s + 1, 1))


@pytest.mark.parametrize(("converged_after_s", "success"), [(9, True), (10, True), (11, False), (25, False)])
def test_convergence_after_the_window_is_no_success(converged_after_s: int, success: bool) -> None:
    """The estimate is right all along; only the instant of convergence (the window is 10 s after the first
    update) decides."""
    stamps, pose = _run()
    assert global_success(stamps, pose, T0 + converged_after_s * S, stamps, pose, CHECK) is success


def test_never_converged_or_wrong_at_the_end_is_no_success() -> None:
    stamps, pose = _run()
    assert not global_success(stamps, pose, None, stamps, pose, CHECK)
    wrong_end = pose.copy()
    wrong_end[-1, 0] += 0.6  # 0.6 m off at the end of the log > max_xy_m = 0.5
    assert not global_success(stamps, wrong_end, T0 + 5 * S, stamps, pose, CHECK)
    near = pose + np.array([0.3, -0.3, 0.15])  # √(0.3² + 0.3²) = 0.42 m ≤ 0.5 m, 0.15 rad ≤ 0.2 rad
    assert global_success(stamps, near, T0 + 5 * S, stamps, pose, CHECK)
