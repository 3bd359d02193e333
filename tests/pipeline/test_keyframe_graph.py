"""The keyframe graph's edge information describes the edge error the pose graph minimizes."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import ScanMatchConfig
from doorbatch.pipeline.poses.keyframe_graph import KeyframeGraph
from doorbatch.pipeline.poses.pose_graph import edge_errors

_angle = st.floats(-np.pi, np.pi)


@settings(max_examples=60, deadline=None)
@given(_angle, _angle, st.floats(-0.05, 0.05), st.floats(-0.05, 0.05), st.floats(-0.02, 0.02), _angle)
def test_a_map_frame_displacement_of_the_measured_pose_costs_its_map_frame_mahalanobis_distance(
        yaw_first: float, yaw_second: float, dx: float, dy: float, dyaw: float, axis_yaw: float) -> None:
    """A loop/sequential edge from a match with covariance Σ (map frame, e.g. 30 cm along a corridor axis at
    ``axis_yaw``, 1 cm across): moving the second node by δ in the map frame costs eᵀΩe = δᵀ Σ⁻¹ δ whatever the
    two headings (the edge information must be expressed in the frame of the error, the measured pose's)."""
    cfg = ScanMatchConfig(graph_min_std_m=1e-6, graph_min_std_deg=1e-6)
    c, s = np.cos(axis_yaw), np.sin(axis_yaw)
    rot = np.array([[c, -s], [s, c]])
    sigma = np.zeros((3, 3))
    sigma[:2, :2] = rot @ np.diag([0.3**2, 0.01**2]) @ rot.T
    sigma[2, 2] = np.radians(1.0) ** 2
    first = np.array([1.0, -2.0, yaw_first])
    second = np.array([4.0, 1.5, yaw_second])
    graph = KeyframeGraph(poses=[first])
    graph.add_sequential(second, sigma, cfg)
    graph.add_loop(0, second, sigma, cfg)
    edges = graph.edges()
    delta = np.array([dx, dy, dyaw])
    moved = np.stack([first, second + delta])
    errors = edge_errors(moved, edges)
    chi2 = np.einsum("ea,eab,eb->e", errors, edges.information, errors)
    expected = delta @ np.linalg.solve(sigma, delta)
    np.testing.assert_allclose(chi2, expected, rtol=2e-2, atol=1e-6)
