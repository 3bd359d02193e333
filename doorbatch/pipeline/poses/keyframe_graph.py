"""The scan-matching front end's pose graph: keyframe poses, sequential and loop edges, and their uncertainty.

Node k is the k-th keyframe. A sequential edge joins consecutive keyframes with the front end's relative pose
z = x_{k−1}⁻¹ ⊕ x_k; a loop edge joins an old keyframe a to the newest with z = x_a⁻¹ ⊕ x_match. A measurement
made in the map frame with covariance Σ (x_{k−1} or x_a held fixed) gives the edge error
e = t2v(Z⁻¹ X_i⁻¹ X_j) (:mod:`.pose_graph`) the covariance Cov(e) = Gᵀ Σ G, G = diag(R(θ_j), 1) of the edge's
*second* node, the measured pose (e's translation is R_zᵀ R_iᵀ δt_j = R_jᵀ δt_j);
``graph_min_std_m`` / ``graph_min_std_deg`` are added to its standard deviations (variances) for the model
error PLICP's covariance leaves out. The uncertainty accumulated since the last accepted loop closure
compounds the sequential edges to first order, Σ ← J Σ Jᵀ + G Cov(e) Gᵀ,
J = [[1, 0, −Δy], [0, 1, Δx], [0, 0, 1]] with (Δx, Δy) the edge's translation in the map frame; it sizes the
next loop search (:mod:`.loop_closure`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from doorbatch.config import ScanMatchConfig
from doorbatch.geometry.se2 import compounded_covariance, frame_rotation, relative
from doorbatch.pipeline.poses.pose_graph import PoseGraphEdges, PoseGraphSolution, optimize_pose_graph

FloatArray = npt.NDArray[np.float64]


def edge_covariance(covariance_map: npt.ArrayLike, measured_pose: npt.ArrayLike, cfg: ScanMatchConfig) -> FloatArray:
    """Cov(e) = Gᵀ Σ G + diag(graph_min_std_m², graph_min_std_m², graph_min_std_deg²), G of the measured (second)
    pose (module docstring)."""
    g = frame_rotation(float(np.asarray(measured_pose, dtype=np.float64)[2]))
    floor = np.array([cfg.graph_min_std_m, cfg.graph_min_std_m, math.radians(cfg.graph_min_std_deg)]) ** 2
    cov: FloatArray = g.T @ np.asarray(covariance_map, dtype=np.float64) @ g + np.diag(floor)
    return cov


@dataclass(slots=True)
class KeyframeGraph:
    """Mutable pose graph of the keyframes (module docstring); node 0 is the first keyframe, held fixed."""

    poses: list[FloatArray]
    first: list[int] = field(default_factory=list)
    second: list[int] = field(default_factory=list)
    measurement: list[FloatArray] = field(default_factory=list)
    covariance: list[FloatArray] = field(default_factory=list)
    robust: list[bool] = field(default_factory=list)
    uncertainty: FloatArray = field(default_factory=lambda: np.zeros((3, 3)))
    last_search_path_m: float = -math.inf  # path length at the last loop search
    last_closure_path_m: float = -math.inf  # path length at the last accepted loop closure

    @property
    def n_loops(self) -> int:
        """Number of loop edges."""
        return sum(self.robust)

    def add_sequential(self, pose: npt.ArrayLike, covariance_map: npt.ArrayLike, cfg: ScanMatchConfig) -> None:
        """A new keyframe at ``pose``, joined to the previous one; the accumulated uncertainty grows."""
        prev = self.poses[-1]
        new = np.asarray(pose, dtype=np.float64).copy()
        cov = edge_covariance(covariance_map, new, cfg)
        self._add(len(self.poses) - 1, len(self.poses), relative(prev, new), cov, robust=False)
        self.poses.append(new)
        g = frame_rotation(float(new[2]))
        self.uncertainty = compounded_covariance(self.uncertainty, new[:2] - prev[:2], g @ cov @ g.T)

    def add_loop(self, anchor: int, matched_pose: npt.ArrayLike, covariance_map: npt.ArrayLike,
                 cfg: ScanMatchConfig) -> None:
        """A loop edge from keyframe ``anchor`` to the newest, which the match placed at ``matched_pose``."""
        a = self.poses[anchor]
        self._add(anchor, len(self.poses) - 1, relative(a, matched_pose),
                  edge_covariance(covariance_map, matched_pose, cfg),
                  robust=True)

    def _add(self, i: int, j: int, z: FloatArray, cov: FloatArray, *, robust: bool) -> None:
        self.first.append(i)
        self.second.append(j)
        self.measurement.append(z)
        self.covariance.append(cov)
        self.robust.append(robust)

    def edges(self) -> PoseGraphEdges:
        """The edges as arrays."""
        information = np.linalg.inv(np.asarray(self.covariance).reshape(-1, 3, 3))
        return PoseGraphEdges(np.asarray(self.first, dtype=np.int64), np.asarray(self.second, dtype=np.int64),
                              np.asarray(self.measurement).reshape(-1, 3), np.asarray(information, dtype=np.float64),
                              np.asarray(self.robust, dtype=bool))

    def optimize(self, cfg: ScanMatchConfig) -> PoseGraphSolution:
        """Optimize all poses (:func:`optimize_pose_graph`) and take the solution as the new poses."""
        solution = optimize_pose_graph(np.stack(self.poses), self.edges(), huber_sigmas=cfg.graph_huber_sigmas,
                                       outlier_chi2=cfg.graph_outlier_chi2, max_iterations=cfg.graph_max_iterations)
        self.poses = list(solution.poses.copy())
        return solution

    def drop_last_edge(self) -> None:
        """Remove the newest edge (a loop edge the χ² gate switched off)."""
        for items in (self.first, self.second, self.measurement, self.covariance, self.robust):
            items.pop()

    def closed(self, path_m: float) -> None:
        """An accepted loop closure at path length ``path_m``: the newest keyframe is fixed against the old map."""
        self.uncertainty = np.zeros((3, 3))
        self.last_closure_path_m = path_m
