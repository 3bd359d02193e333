"""AMCL's heaviest-cluster pose estimate (localize/clusters.py): known clouds with known answers."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from doorbatch.config import DoorbatchConfig
from doorbatch.pipeline.localize.clusters import cluster_labels, heaviest_cluster_mean
from doorbatch.pipeline.localize.particles import ParticleSet

BIN_XY, BIN_YAW = 0.5, math.radians(10.0)


def _cloud(poses: np.ndarray, weights: np.ndarray) -> ParticleSet:
    ps = ParticleSet.gaussian(np.zeros(3), np.full(3, 1e-9), len(poses), np.random.default_rng(0))
    ps.pose[:] = poses
    ps.weight[:] = weights / weights.sum()
    return ps


def test_two_hypotheses_report_the_heavier_one_not_the_point_between() -> None:
    """A global start's two hypotheses 8 m apart (a symmetric corridor), 60 % and 40 % of the weight: the
    weighted mean lies 4 m from both; AMCL's estimate is the heavier one's mean."""
    rng = np.random.default_rng(1)
    a = np.column_stack([rng.normal(2.0, 0.05, 300), rng.normal(0.0, 0.05, 300), rng.normal(0.0, 0.01, 300)])
    b = np.column_stack([rng.normal(10.0, 0.05, 200), rng.normal(0.0, 0.05, 200), rng.normal(0.0, 0.01, 200)])
    cloud = _cloud(np.vstack([a, b]), np.ones(500))
    labels = cluster_labels(cloud.pose, BIN_XY, BIN_YAW)
    assert len(set(labels[:300])) == 1 and len(set(labels[300:])) == 1 and labels[0] != labels[300]
    mean = heaviest_cluster_mean(cloud, BIN_XY, BIN_YAW)
    np.testing.assert_allclose(mean, a.mean(axis=0), atol=1e-6)  # circular mean of the yaw
    assert abs(cloud.mean_and_covariance()[0][0] - 5.2) < 0.05


def test_bins_that_touch_at_a_corner_or_across_a_heading_bin_are_one_cluster() -> None:
    """A diagonal chain of particles one bin apart in x, y and heading is one cluster (26 neighbours); two bins
    apart it is not."""
    step = np.array([BIN_XY, BIN_XY, BIN_YAW])
    chain = (np.arange(6)[:, None] + 0.5) * step
    assert len(set(cluster_labels(chain, BIN_XY, BIN_YAW))) == 1
    assert len(set(cluster_labels(chain[::2], BIN_XY, BIN_YAW))) == 3


@settings(max_examples=50, deadline=None)
@given(st.integers(1, 400), st.integers(0, 2**31 - 1))
def test_a_cloud_within_one_bin_gives_the_weighted_mean(n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(0.01, 0.49, n), rng.uniform(0.01, 0.49, n), rng.uniform(0.001, 0.17, n)])
    cloud = _cloud(poses, rng.uniform(0.1, 1.0, n))
    np.testing.assert_allclose(heaviest_cluster_mean(cloud, BIN_XY, BIN_YAW), cloud.mean_and_covariance()[0],
                               atol=1e-12)


def test_an_amcl_parameter_file_reports_the_heaviest_cluster() -> None:
    assert DoorbatchConfig().localize.pose_estimate == "mean"
    from doorbatch.amcl_params import translate_amcl_parameters

    assert translate_amcl_parameters({}).tree["localize"]["pose_estimate"] == "heaviest_cluster"
