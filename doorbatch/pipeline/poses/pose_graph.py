"""SE(2) pose-graph optimization: sparse Levenberg–Marquardt with a robust kernel on loop edges.

Nodes are poses x_i = (t_i, θ_i) in the map frame. An edge (i, j) measures the pose of x_j in the frame of
x_i, z_ij = (t_z, θ_z), with information Ω_ij. Its error is (g2o's SE(2) edge, Grisetti et al., "A tutorial
on graph-based SLAM", 2010, eq. 30)

    e_ij = t2v(Z_ij⁻¹ X_i⁻¹ X_j) = ( R_zᵀ (R_iᵀ (t_j − t_i) − t_z),  wrap(θ_j − θ_i − θ_z) ),

with the analytic Jacobians (the tutorial's eq. 32–33)

    ∂e/∂t_i = −R_zᵀ R_iᵀ,   ∂e_xy/∂θ_i = R_zᵀ (∂R_iᵀ/∂θ) (t_j − t_i),   ∂e_θ/∂θ_i = −1,
    ∂e/∂t_j =  R_zᵀ R_iᵀ,   ∂e_θ/∂θ_j = 1,

and the graph minimizes F(x) = Σ ρ_ij(e_ijᵀ Ω_ij e_ij) over all poses but the first (held fixed: the gauge).
Sequential edges count in full (ρ(s) = s); loop edges through the Huber kernel ρ(s) = s for √s ≤ k, 2k√s − k²
beyond (iteratively reweighted, w = min(1, k/√s)): convex, so a true loop edge with a large initial error
still closes, while a false one pulls with bounded force. After convergence loop edges whose χ² = eᵀΩe
exceeds ``outlier_chi2`` are switched off and the graph is solved again (the χ² gate of ORB-SLAM and
Cartographer's rejection of constraints that disagree with the optimized graph), so that a false loop edge
leaves no trace. Each Levenberg–Marquardt step solves (H + λ diag H) δ = −g with H = Σ Jᵀ W Ω J, g = Σ Jᵀ W Ω e
assembled as a scipy.sparse matrix (3N × 3N, block-tridiagonal plus the loops).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import rotation_matrix

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True, slots=True)
class PoseGraphEdges:
    """E relative-pose measurements: the pose of node ``second`` in the frame of node ``first``.

    Attributes:
        first: (E,) node index i.
        second: (E,) node index j.
        measurement: (E, 3) z_ij = x_i⁻¹ ⊕ x_j as measured (x, y in m, yaw in rad).
        information: (E, 3, 3) Ω_ij, the inverse of the covariance of e_ij (the measured x_j's frame).
        robust: (E,) loop edges: Huber kernel and the χ² gate (sequential edges are trusted in full).
    """

    first: IntArray
    second: IntArray
    measurement: FloatArray
    information: FloatArray
    robust: BoolArray

    @property
    def size(self) -> int:
        """Number of edges E."""
        return int(self.first.shape[0])


@dataclass(frozen=True, slots=True)
class PoseGraphSolution:
    """Optimized poses, which edges were kept, and each edge's χ² = eᵀΩe at the solution."""

    poses: FloatArray  # (N, 3)
    active: BoolArray  # (E,) False for loop edges switched off by the χ² gate
    chi2: FloatArray  # (E,)


def edge_errors(poses: FloatArray, edges: PoseGraphEdges) -> FloatArray:
    """e_ij = t2v(Z_ij⁻¹ X_i⁻¹ X_j) for every edge, (E, 3) (module docstring)."""
    xi, xj = poses[edges.first], poses[edges.second]
    ri_t = np.swapaxes(rotation_matrix(xi[:, 2]), -1, -2)
    rz_t = np.swapaxes(rotation_matrix(edges.measurement[:, 2]), -1, -2)
    local = np.einsum("eab,eb->ea", ri_t, xj[:, :2] - xi[:, :2]) - edges.measurement[:, :2]
    e_xy = np.einsum("eab,eb->ea", rz_t, local)
    e_th = wrap_angle(xj[:, 2] - xi[:, 2] - edges.measurement[:, 2])
    out: FloatArray = np.column_stack([e_xy, e_th])
    return out


def edge_jacobians(poses: FloatArray, edges: PoseGraphEdges) -> tuple[FloatArray, FloatArray]:
    """(A, B) = (∂e/∂x_i, ∂e/∂x_j), each (E, 3, 3) (module docstring)."""
    xi, xj = poses[edges.first], poses[edges.second]
    c, s = np.cos(xi[:, 2]), np.sin(xi[:, 2])
    ri_t = np.swapaxes(rotation_matrix(xi[:, 2]), -1, -2)
    rz_t = np.swapaxes(rotation_matrix(edges.measurement[:, 2]), -1, -2)
    d_ri_t = np.stack([np.stack([-s, c], axis=-1), np.stack([-c, -s], axis=-1)], axis=-2)  # ∂R_iᵀ/∂θ_i
    rzri = rz_t @ ri_t
    n = edges.size
    a = np.zeros((n, 3, 3))
    b = np.zeros((n, 3, 3))
    a[:, :2, :2] = -rzri
    a[:, :2, 2] = np.einsum("eab,eb->ea", rz_t @ d_ri_t, xj[:, :2] - xi[:, :2])
    a[:, 2, 2] = -1.0
    b[:, :2, :2] = rzri
    b[:, 2, 2] = 1.0
    return a, b


def _weights(chi2: FloatArray, robust: BoolArray, huber_sigmas: float) -> FloatArray:
    """IRLS weights: 1 on sequential edges, Huber's min(1, k/√χ²) on loop edges."""
    w = np.ones_like(chi2)
    root = np.sqrt(np.maximum(chi2, 1e-300))
    w[robust] = np.minimum(1.0, huber_sigmas / root[robust])
    return w


def _cost(chi2: FloatArray, robust: BoolArray, huber_sigmas: float) -> float:
    """F = Σ ρ(χ²): χ² on sequential edges, Huber's 2k√χ² − k² beyond k² on loop edges."""
    root = np.sqrt(chi2)
    huber = np.where(root <= huber_sigmas, chi2, 2.0 * huber_sigmas * root - huber_sigmas**2)
    return float(np.sum(np.where(robust, huber, chi2)))


def _chi2(errors: FloatArray, information: FloatArray) -> FloatArray:
    out: FloatArray = np.einsum("ea,eab,eb->e", errors, information, errors)
    return out


def _normal_equations(poses: FloatArray, edges: PoseGraphEdges, weights: FloatArray
                      ) -> tuple[sp.csc_matrix, FloatArray]:
    """Sparse H = Σ Jᵀ W Ω J and g = Σ Jᵀ W Ω e over the free nodes 1 … N−1 (node 0 is the gauge)."""
    n = poses.shape[0]
    err = edge_errors(poses, edges)
    a, b = edge_jacobians(poses, edges)
    omega = edges.information * weights[:, None, None]
    blocks = {(0, 0): a, (0, 1): b}
    ends = (edges.first, edges.second)
    rows, cols, vals = [], [], []
    g = np.zeros(3 * n)
    idx3 = np.arange(3)
    for p, jp in blocks.items():
        jp_t_omega = np.swapaxes(jp, -1, -2) @ omega
        np.add.at(g, (3 * ends[p[1]][:, None] + idx3).ravel(), np.einsum("eab,eb->ea", jp_t_omega, err).ravel())
        for q, jq in blocks.items():
            block = jp_t_omega @ jq
            r = 3 * ends[p[1]][:, None, None] + idx3[None, :, None]
            c = 3 * ends[q[1]][:, None, None] + idx3[None, None, :]
            rows.append(np.broadcast_to(r, block.shape).ravel())
            cols.append(np.broadcast_to(c, block.shape).ravel())
            vals.append(block.ravel())
    h = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * n, 3 * n))
    return h.tocsc()[3:, 3:], g[3:]


def _solve_weighted(poses: FloatArray, edges: PoseGraphEdges, active: BoolArray, *, huber_sigmas: float,
                    max_iterations: int, tolerance: float) -> FloatArray:
    """Levenberg–Marquardt with IRLS weights re-derived at every accepted step (module docstring)."""
    used = PoseGraphEdges(edges.first[active], edges.second[active], edges.measurement[active],
                          edges.information[active], edges.robust[active])
    x = poses.copy()
    chi2 = _chi2(edge_errors(x, used), used.information)
    cost = _cost(chi2, used.robust, huber_sigmas)
    damping = 1e-4
    for _ in range(max_iterations):
        h, g = _normal_equations(x, used, _weights(chi2, used.robust, huber_sigmas))
        diag = h.diagonal()
        step = spla.spsolve(h + sp.diags(damping * np.maximum(diag, 1e-12)), -g)
        trial = x.copy()
        trial[1:] += step.reshape(-1, 3)
        trial[:, 2] = wrap_angle(trial[:, 2])
        trial_chi2 = _chi2(edge_errors(trial, used), used.information)
        trial_cost = _cost(trial_chi2, used.robust, huber_sigmas)
        if trial_cost <= cost:
            converged = cost - trial_cost <= tolerance * max(cost, 1e-12)
            x, chi2, cost = trial, trial_chi2, trial_cost
            damping = max(damping / 10.0, 1e-9)
            if converged:
                break
        else:
            damping *= 10.0
            if damping > 1e8:
                break
    return x


def optimize_pose_graph(poses: npt.ArrayLike, edges: PoseGraphEdges, *, huber_sigmas: float = 3.0,
                        outlier_chi2: float = 16.27, max_iterations: int = 50, tolerance: float = 1e-6
                        ) -> PoseGraphSolution:
    """Minimize Σ ρ(e_ijᵀ Ω_ij e_ij) over the poses (node 0 fixed), then drop loop edges beyond the χ² gate.

    Args:
        poses: (N, 3) initial poses (x, y, yaw), map frame.
        edges: The measurements; node indices in [0, N).
        huber_sigmas: Huber threshold k on the loop edges' Mahalanobis distance √(eᵀΩe).
        outlier_chi2: A loop edge whose χ² exceeds this at the optimum is switched off and the graph solved
            again without it (16.27: the 99.9 % quantile of χ² with 3 degrees of freedom), one edge at a time,
            the worst first.
        max_iterations: Levenberg–Marquardt iterations per solve.
        tolerance: Stop when the cost falls by less than this fraction.

    Returns:
        The optimized poses, the kept edges and each edge's χ² at the solution.

    Raises:
        ValueError: poses is not (N, 3) or an edge names a node outside [0, N).
    """
    x = np.asarray(poses, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"poses must be (N, 3); got {x.shape}")
    if edges.size and (min(edges.first.min(), edges.second.min()) < 0
                       or max(edges.first.max(), edges.second.max()) >= x.shape[0]):
        raise ValueError("an edge names a node outside the graph")
    active = np.ones(edges.size, dtype=bool)
    while True:
        if x.shape[0] > 1 and edges.size:
            x = _solve_weighted(x, edges, active, huber_sigmas=huber_sigmas, max_iterations=max_iterations,
                                tolerance=tolerance)
        chi2 = _chi2(edge_errors(x, edges), edges.information) if edges.size else np.zeros(0)
        beyond = np.flatnonzero(active & edges.robust & (chi2 > outlier_chi2))
        if beyond.size == 0:
            return PoseGraphSolution(x, active, chi2)
        active[beyond[np.argmax(chi2[beyond])]] = False
