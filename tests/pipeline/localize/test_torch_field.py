"""The torch backend of the likelihood field: the same distances and log-likelihoods as NumPy, on every device
torch offers here (CPU always, CUDA when present), and clear errors when it cannot run."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from mcl_sim import asymmetric_room, polyline, room_map, scan_beams

from doorbatch.config import LocalizeConfig
from doorbatch.errors import OptionalDependencyError, UsageError
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    build_distance_field,
    endpoint_distances,
    field_log_likelihood,
    skipped_field_log_likelihood,
)
from doorbatch.pipeline.localize.run import localization_field

torch = pytest.importorskip("torch")
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA"))]
RES = 0.05


def _random_field(device: str | None) -> tuple[object, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    occ = np.where(rng.random((80, 100)) < 0.05, 100, 0).astype(np.int8)
    field = build_distance_field(OccupancyMap(occ, RES, 1.3, -0.7, 0.4), 0.5, torch_device=device)
    # poses over the map and beyond it (end points off every edge), with one NaN and one infinite pose
    pose = np.column_stack([rng.uniform(-2, 8, 3000), rng.uniform(-3, 7, 3000), rng.uniform(-4, 4, 3000)])
    pose[7] = np.nan
    pose[8, 0] = np.inf
    pts = rng.uniform(-4, 4, (37, 2))
    return field, pose, pts


@pytest.mark.parametrize("device", DEVICES)
def test_torch_distances_are_numpys_cells(device: str) -> None:
    numpy_field, pose, pts = _random_field(None)
    torch_field, _, _ = _random_field(device)
    reference = endpoint_distances(numpy_field, pose, pts)
    got = endpoint_distances(torch_field, pose, pts)
    assert got.dtype == np.float32 and got.shape == reference.shape == (3000, 37)
    # the same float32 steps in the same order: the same cell but for a last-ulp cosine on a cell border
    same = got == reference
    assert same.mean() > 0.9999, same.mean()
    assert np.all(np.abs(got - reference) <= 2 * RES * np.sqrt(2) + 1e-6)
    assert np.all(got[7] == np.float32(0.5)) and np.all(got[8] == np.float32(0.5))  # NaN/inf: off the map
    assert (got < 0.5).mean() > 0.1  # near obstacles too, not only off-map


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("combination", list(BeamCombination))
def test_torch_log_likelihood_is_numpys(device: str, combination: BeamCombination) -> None:
    numpy_field = build_distance_field(room_map(), 2.0)
    torch_field = build_distance_field(room_map(), 2.0, torch_device=device)
    rng = np.random.default_rng(19)
    pose = np.column_stack([rng.uniform(-1, 9, 2500), rng.uniform(-1, 6, 2500), rng.uniform(-4, 4, 2500)])
    pts = rng.uniform(-6, 6, (61, 2))
    reference = field_log_likelihood(numpy_field, pose, pts, 0.95, 0.05, 0.1, 12.0, combination)
    got = field_log_likelihood(torch_field, pose, pts, 0.95, 0.05, 0.1, 12.0, combination)
    assert np.ptp(reference) > 1.0  # particles that differ, so that agreeing means something
    assert np.allclose(got, reference, rtol=1e-5, atol=1e-6)
    assert field_log_likelihood(torch_field, pose[:0], pts, 0.95, 0.05, 0.1, 12.0).shape == (0,)
    assert np.all(field_log_likelihood(torch_field, pose, pts[:0], 0.95, 0.05, 0.1, 12.0) == 0.0)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("combination", list(BeamCombination))
@pytest.mark.parametrize("support", ["posterior", "particles"])
def test_torch_beam_skipping_is_numpys(device: str, combination: BeamCombination, support: str) -> None:
    """MCL's weighing of a converged cloud on the device: the same beams skipped, the same log-likelihoods."""
    truth = np.array([4.0, 2.5, 0.3])
    person = polyline((5.6, 2.4), (5.9, 2.4), (5.9, 2.9), (5.6, 2.9), (5.6, 2.4))  # in the scan, not the map
    beams = scan_beams(np.concatenate([asymmetric_room(), person]), truth)
    rng = np.random.default_rng(3)
    pose = truth + rng.normal(0.0, [0.03, 0.03, 0.01], (4000, 3))
    weight = rng.dirichlet(np.ones(4000))
    config = LocalizeConfig(beam_skip_support=support)  # type: ignore[arg-type]
    numpy_field = build_distance_field(room_map(), 2.0)
    torch_field = build_distance_field(room_map(), 2.0, torch_device=device)
    reference, skipped = skipped_field_log_likelihood(numpy_field, pose, weight, beams.points_base, config, 12.0,
                                                      combination)
    got, got_skipped = skipped_field_log_likelihood(torch_field, pose, weight, beams.points_base, config, 12.0,
                                                    combination)
    assert skipped >= 3 and got_skipped == skipped  # the person's beams
    assert np.ptp(reference) > 0.5
    assert np.allclose(got, reference, rtol=1e-5, atol=1e-5)
    flipped, _ = skipped_field_log_likelihood(torch_field, pose[::-1], weight[::-1], beams.points_base, config, 12.0,
                                              combination)  # views with negative strides, as NumPy takes them
    assert np.allclose(flipped, reference[::-1], rtol=1e-5, atol=1e-5)
    # a cloud that has not converged skips nothing, on both
    wide = truth + rng.normal(0.0, [1.0, 1.0, 0.5], (4000, 3))
    unskipped = field_log_likelihood(numpy_field, wide, beams.points_base, config.z_hit, config.z_rand,
                                     config.sigma_hit, 12.0, combination)
    got, got_skipped = skipped_field_log_likelihood(torch_field, wide, weight, beams.points_base, config, 12.0,
                                                    combination)
    assert got_skipped == 0 and np.allclose(got, unskipped, rtol=1e-5, atol=1e-5)


def test_the_config_picks_the_backend() -> None:
    assert localization_field(room_map(), LocalizeConfig()).torch_device is None
    cfg = LocalizeConfig(backend="torch", torch_device="cpu")
    assert localization_field(room_map(), cfg).torch_device == "cpu"


def test_a_device_torch_cannot_use_is_a_usage_error() -> None:
    with pytest.raises(UsageError, match="torch_device 'gpu0'"):
        localization_field(room_map(), LocalizeConfig(backend="torch", torch_device="gpu0"))
    if not torch.cuda.is_available():
        with pytest.raises(UsageError, match="no CUDA device"):
            localization_field(room_map(), LocalizeConfig(backend="torch", torch_device="cuda"))


def test_torch_missing_is_an_optional_dependency_error(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "torch", None)  # import torch now raises ImportError
    with pytest.raises(OptionalDependencyError, match=r"doorbatch\[torch\]"):
        localization_field(room_map(), LocalizeConfig(backend="torch", torch_device="cpu"))
