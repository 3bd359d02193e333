"""The RBPF's door-aware weighing on a torch device: NumPy's scores, associations, skipped beams and
log-likelihoods (to rounding), on every device torch offers here (CPU always, CUDA when present)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mcl_sim import asymmetric_room, polyline, room_map, scan_beams
from test_door_likelihood import CONFIG, RANGE_MAX, random_case

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet
from doorbatch.pipeline.localize.door_likelihood import _numpy_scores, beam_model
from doorbatch.pipeline.localize.door_prior import UNIFORM, DoorPrior
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    build_distance_field,
    endpoint_distances,
    skip_unexplained,
)
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import DoorBeamInformation, door_beam_information, tracked_log_likelihood
from doorbatch.pipeline.localize.torch_door_likelihood import door_scores, skipped_door_log_likelihood

torch = pytest.importorskip("torch")
DEVICES = ["cpu", pytest.param("cuda", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA"))]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("prior", [UNIFORM, DoorPrior(0.3, math.radians(3.0) ** 2)])
def test_torch_door_scores_are_numpys(device: str, prior: DoorPrior) -> None:
    """Random doors, end points and door beliefs (half the doors at their prior, a few end points NaN): the same
    association, the same scores to rounding."""
    rng = np.random.default_rng(8)
    static, pts, doors, mean, var = random_case(rng, 700, 60, 10)
    static = static.astype(np.float32)
    pts[0, :5] = np.nan
    unobserved = np.where(np.arange(10) % 2 == 0, 0.1, np.inf)
    model = beam_model(CONFIG, RANGE_MAX)
    ref_score, ref_assoc = _numpy_scores(static, pts, doors, mean, var, model, None, unobserved, prior)
    score, assoc = door_scores(*(torch.as_tensor(a, device=device) for a in (static, pts)), doors,
                               *(torch.as_tensor(a, device=device) for a in (mean, var)), model, unobserved, prior)
    got_score, got_assoc = score.cpu().numpy(), assoc.cpu().numpy()
    assert got_score.dtype == np.float32 and got_assoc.dtype == np.int16
    assert np.mean(ref_assoc >= 0) > 0.3 and len(set(ref_assoc[ref_assoc >= 0].tolist())) == 10  # every door wins
    assert (var >= unobserved).any() and (var < unobserved).any()  # both forms of the door term
    assert np.mean(got_assoc == ref_assoc) > 0.9999
    np.testing.assert_array_equal(np.isnan(got_score), np.isnan(ref_score))
    # A score above ~30 is a beam the random term explains (z_hit·e^(−score/2) < 1e-7 of it): there the prior's
    # closed form takes erf(u_hi) − erf(u_lo) of two values next to ±1, a difference of a few ulps that CUDA's
    # erf and libm's round apart (seen: 77.66 against 77.74). What the filter uses, pz, is the same.
    same = (got_assoc == ref_assoc) & (ref_score < 30.0)
    assert same.mean() > 0.5
    np.testing.assert_allclose(got_score[same], ref_score[same], rtol=1e-5, atol=1e-5)
    pz = [model.z_hit * np.exp(-0.5 * s) + model.rand_term for s in (got_score, ref_score)]
    np.testing.assert_allclose(pz[0], pz[1], rtol=1e-5, equal_nan=True)


# The asymmetric room with a door in its south wall standing open into the room at 1.2 rad (a leaf the static map
# lacks), a closed one in its west wall that the particles have not observed, and a person the map lacks.
DOORS = DoorSet(hinge=np.array([[6.2, 0.0], [0.0, 2.5]]), length=np.array([0.9, 0.8]),
                closed_yaw=np.array([0.0, math.pi / 2]), angle_min=np.zeros(2), angle_max=np.full(2, 1.6))
LEAF = polyline((6.2, 0.0), (6.2 + 0.9 * math.cos(1.2), 0.9 * math.sin(1.2)))
PERSON = polyline((3.6, 2.4), (3.9, 2.4), (3.9, 2.7), (3.6, 2.7), (3.6, 2.4))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("combination", list(BeamCombination))
def test_a_tracked_cloud_with_doors_is_weighed_on_the_device_as_on_the_host(device: str,
                                                                            combination: BeamCombination) -> None:
    """A converged cloud weighed by the RBPF: the leaf's beams go to the door, the person's are skipped, and the
    log-likelihoods and the association are NumPy's."""
    truth = np.array([4.5, 1.8, -0.4])
    beams = scan_beams(np.concatenate([asymmetric_room(), LEAF, PERSON]), truth, max_beams=90)
    rng = np.random.default_rng(11)
    n = 3000
    particles = ParticleSet(truth + rng.normal(0.0, [0.03, 0.03, 0.01], (n, 3)), rng.dirichlet(np.ones(n)),
                            np.column_stack([rng.normal(1.2, 0.05, n), np.zeros(n)]),
                            np.column_stack([np.full(n, 0.01), np.full(n, 0.5)]))
    config = LocalizeConfig(tracking_door_prior=True)
    numpy_field = build_distance_field(room_map(), 2.0)
    torch_field = build_distance_field(room_map(), 2.0, torch_device=device)
    reference, association = tracked_log_likelihood(particles, beams, numpy_field, DOORS, config, combination)
    got, info = tracked_log_likelihood(particles, beams, torch_field, DOORS, config, combination)
    assert isinstance(association, np.ndarray) and isinstance(info, DoorBeamInformation)  # each where it lies
    assert info.info.shape == info.info_angle.shape == (n, 2)
    ref_info = door_beam_information(association, particles.pose, beams.points_base, DOORS, config)
    assert np.mean(ref_info.info[:, 0] > 0) > 0.9  # the open leaf explains beams, and says where it stands
    near = ref_info.info[:, 0] > 0
    assert abs(np.median(ref_info.info_angle[near, 0] / ref_info.info[near, 0]) - 1.2) < 0.02
    for a, b in zip(info, ref_info, strict=True):  # the same beams on each door, the same angles
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-9)
    assert np.ptp(reference) > 0.5
    np.testing.assert_allclose(got, reference, rtol=1e-5, atol=1e-5)
    again, info_again = tracked_log_likelihood(particles, beams, torch_field, DOORS, config, combination)
    assert isinstance(info_again, DoorBeamInformation)  # the same seed, the same bits: no atomic adds on a GPU
    assert np.array_equal(again, got) and all(np.array_equal(a, b) for a, b in zip(info_again, info, strict=True))
    *_, skipped = skipped_door_log_likelihood(torch_field, particles.pose, particles.weight, beams.points_base,
                                              DOORS, particles.door_mean, particles.door_var, config,
                                              beams.range_max_m, combination, np.full(2, 0.3))
    from doorbatch.pipeline.localize.door_likelihood import door_log_likelihood_at_poses

    dl = door_log_likelihood_at_poses(endpoint_distances(numpy_field, particles.pose, beams.points_base),
                                      particles.pose, beams.points_base, DOORS, particles.door_mean,
                                      particles.door_var, config, beams.range_max_m, unobserved_var=np.full(2, 0.3))
    _, ref_skipped = skip_unexplained(dl.beam_likelihood, particles.weight, particles.pose, config,
                                      beams.range_max_m, combination)
    assert ref_skipped >= 2 and skipped == ref_skipped  # the person's beams


@pytest.mark.parametrize("device", DEVICES)
def test_no_beams_and_no_doors_in_reach(device: str) -> None:
    field = build_distance_field(room_map(), 2.0, torch_device=device)
    pose = np.array([[4.0, 2.5, 0.0], [4.1, 2.5, 0.1]])
    mean, var = np.zeros((2, 2)), np.full((2, 2), 0.01)
    loglik, info, skipped = skipped_door_log_likelihood(field, pose, np.full(2, 0.5), np.zeros((0, 2)), DOORS,
                                                        mean, var, CONFIG, RANGE_MAX, BeamCombination.PRODUCT)
    assert loglik.tolist() == [0.0, 0.0] and not info.info.any() and info.info.shape == (2, 2) and skipped == 0
    far = DoorSet(hinge=np.array([[60.0, 60.0]]), length=np.array([0.9]), closed_yaw=np.zeros(1),
                  angle_min=np.zeros(1), angle_max=np.ones(1))
    pts = np.array([[1.0, 0.0], [0.0, 1.0]])
    loglik, info, _ = skipped_door_log_likelihood(field, pose, np.full(2, 0.5), pts, far, mean[:, :1], var[:, :1],
                                                  CONFIG, RANGE_MAX, BeamCombination.PRODUCT)
    assert not info.info.any() and np.isfinite(loglik).all()


def test_more_doors_than_the_association_holds_is_an_error_as_on_the_host() -> None:
    field = build_distance_field(room_map(), 2.0, torch_device="cpu")
    n = 40_000
    many = DoorSet(hinge=np.zeros((n, 2)), length=np.ones(n), closed_yaw=np.zeros(n), angle_min=np.zeros(n),
                   angle_max=np.ones(n))
    with pytest.raises(ValueError, match="40000 doors do not fit the int16 association"):
        skipped_door_log_likelihood(field, np.zeros((1, 3)), np.ones(1), np.ones((3, 2)), many, np.zeros((1, n)),
                                    np.zeros((1, n)), CONFIG, RANGE_MAX, BeamCombination.PRODUCT)
