"""What a localization run produces, per filter update (U updates, D doors)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from doorbatch.io.log_clock import LogClock

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class StillDoorStates:
    """Door estimates of the RBPF's updates that held the pose (the robot standing still; ``door_update_when_still``):
    stamps_ns (S,), mean and std (S, D) as :class:`LocalizationResult`'s, observed (S, D)."""

    stamps_ns: npt.NDArray[np.int64]
    mean: FloatArray
    std: FloatArray
    observed: npt.NDArray[np.bool_]


@dataclass(frozen=True)
class LocalizationResult:
    """The estimate after every filter update.

    Attributes:
        stamps_ns: (U,) scan stamps of the updates.
        pose: (U, 3) weighted mean pose (map frame); cov: (U, 3, 3) weighted covariance (x, y, yaw).
        odom: (U, 3) the odometry pose at each update (for the map→odom transform).
        n_particles: (U,) particles after the update; neff: (U,) effective sample size before resampling.
        door_mean, door_std: (U, D) per door the weighted angle (rad, relative to closed_yaw) and std;
        door_observed: (U, D) whether the door was measured in that update's scan by particles holding at least
            ``localize.door_observed_min_share`` of the weight.
        particles: (U, K, 3) a decimated draw of the particles per update (for the annotated MCAP).
        converged_ns: first stamp at which the filter counted as converged (None: never; tracking runs
            start converged); ambiguous: global localization ended with several distinct hypotheses.
        warnings: what the run found wrong with its input or its course (a command writes them to its manifest).
        lost_ns: the stamps at which an episode of being lost began.
        door_ids: (D,) the map's door_id of each door column (:attr:`door_id`).
        still_doors: the RBPF's door estimates at scans where the robot stood still and the pose was held;
            door_states.parquet holds these rows and those of the updates, in time order.
    """

    log: str
    method: str
    stamps_ns: npt.NDArray[np.int64]
    pose: FloatArray
    cov: FloatArray
    odom: FloatArray
    n_particles: npt.NDArray[np.int32]
    neff: FloatArray
    door_mean: FloatArray
    door_std: FloatArray
    door_observed: npt.NDArray[np.bool_]
    particles: FloatArray
    converged_ns: int | None = None
    ambiguous: bool = False
    warnings: list[str] = field(default_factory=list)
    log_clock: LogClock | None = None  # the log's recorder clock against its scan stamps (Recording.log_clock)
    lost_ns: list[int] = field(default_factory=list)  # stamps at which an episode of being lost began
    odom_frame_id: str = ""  # the frame of the odometry the run moved by ("": not known)
    door_ids: npt.NDArray[np.int32] | None = None  # (D,) the map's door_id of each door column; None: 0 … D − 1
    still_doors: StillDoorStates | None = None  # door updates between pose updates (None or empty: none)
    # (U, 3) base_link's pose in the odometry frame as the log's TF tree holds it at each update
    # (Recording.drawn_odometry), for annotated.mcap's map→odom; None: ``odom`` (a bridged restart is not in the tree)
    drawn_odom: FloatArray | None = None

    @property
    def door_id(self) -> npt.NDArray[np.int32]:
        """(D,) the map's door_id (doors.parquet) of each column of door_mean."""
        d = self.door_mean.shape[1]
        return np.arange(d, dtype=np.int32) if self.door_ids is None else np.asarray(self.door_ids, dtype=np.int32)

    def manifest_extra(self) -> dict[str, object]:
        """What a run directory's manifest keeps of the run beyond its tables: seconds from the first update to
        convergence (None: never) and to each loss, and whether global localization ended ambiguous."""
        t0 = int(self.stamps_ns[0])
        return {"converged_after_s": None if self.converged_ns is None else (self.converged_ns - t0) / 1e9,
                "ambiguous": self.ambiguous, "lost_after_s": [(t - t0) / 1e9 for t in self.lost_ns]}

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def __repr__(self) -> str:
        """A line a notebook can show (the arrays' own repr runs to tens of thousands of characters)."""
        span = (int(self.stamps_ns[-1]) - int(self.stamps_ns[0])) / 1e9 if len(self) else 0.0
        return (f"LocalizationResult(log={self.log!r}, method={self.method!r}, updates={len(self)}, "
                f"span_s={span:.1f}, doors={self.door_mean.shape[1]}, lost={len(self.lost_ns)}, "
                f"warnings={len(self.warnings)})")
