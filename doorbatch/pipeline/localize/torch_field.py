"""The likelihood field's hot loop in torch: the optional backend of issue #5, item 5 (``localize.backend: torch``).

Same interface, same arithmetic as :func:`~.likelihood_field.endpoint_distances` and
:func:`~.likelihood_field.field_log_likelihood`, on a torch device: particle poses go to the grid frame in
float64 (:meth:`~.likelihood_field.DistanceField.to_grid`), cos/sin are rounded to float32, and every beam end
point is moved, clamped into the padded field and truncated to its cell in float32, one elementwise operation at
a time in NumPy's order, so the cells looked up are NumPy's (a last-ulp difference of a cosine between libraries
can move an end point lying on a cell border to the neighbouring cell; the tests bound how often).

The padded field goes to the device once per :class:`~.likelihood_field.DistanceField` and stays there. Each call
sends the poses (N × 3 float64) and the end points (B × 2) and brings back the (N, B) distances or, fused, only the
(N,) log-likelihoods: with beam skipping too (:func:`skipped_field_log_likelihood`, MCL's weighing of a converged
cloud), whose support sums and exp round otherwise than NumPy's, so its log-likelihoods equal NumPy's to float32
rounding, not to the bit. Where it pays: on a GPU; on a CPU NumPy is faster (docs/benchmarks.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from doorbatch.errors import OptionalDependencyError, UsageError

if TYPE_CHECKING:
    from doorbatch.config import LocalizeConfig
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination, DistanceField

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
# Particles per block: (block × B) float32 temporaries, ~16 MB each at 60 beams; bounds device memory for any N.
BLOCK_PARTICLES = 65536


def import_torch() -> Any:
    try:
        import torch
    except ImportError as err:
        raise OptionalDependencyError("torch (localize.backend: torch)", "torch") from err
    return torch


def check_device(device: str) -> None:
    """Fail early, before a long run, when ``device`` cannot run the backend.

    Raises:
        OptionalDependencyError: torch is not installed.
        UsageError: the device name is not one torch knows, or it is a CUDA device and none is available.
    """
    torch = import_torch()
    try:
        dev = torch.device(device)
    except RuntimeError as err:
        raise UsageError(f"localize.torch_device {device!r}: {err}") from err
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise UsageError(f"localize.torch_device {device!r}: torch {torch.__version__} sees no CUDA device "
                         "(use localize.backend: numpy, or torch_device: cpu)")


@dataclass(frozen=True)
class _DeviceField:
    """The padded field, flattened, on the device; its padded width and height."""

    padded: Any
    width: int
    height: int


def _device_field(dist_field: DistanceField, device: str) -> _DeviceField:
    """The field's copy on ``device``, made on first use and kept in ``dist_field.device_cache``."""
    cached = dist_field.device_cache.get(device)
    if isinstance(cached, _DeviceField):
        return cached
    torch = import_torch()
    padded = torch.from_numpy(np.ascontiguousarray(dist_field.padded).ravel()).to(device)
    made = _DeviceField(padded, dist_field.width + 2, dist_field.height + 2)
    dist_field.device_cache[device] = made
    return made


def block_distances(field: _DeviceField, grid: Any, cells: Any) -> Any:
    """(n, B) float32 distances for grid-frame poses (n, 3, float64) and end points in cell units (B, 2, float32),
    in the order of ``likelihood_field._chunk_distances`` and ``_gather``."""
    torch = import_torch()
    c = torch.cos(grid[:, 2:3]).float()
    s = torch.sin(grid[:, 2:3]).float()
    gx, gy = grid[:, 0:1].float(), grid[:, 1:2].float()
    bx, by = cells[None, :, 0], cells[None, :, 1]
    col = c * bx
    col -= s * by
    col += gx
    row = s * bx
    row += c * by
    row += gy
    col += 1.0
    row += 1.0
    # NaN (an infinite pose) goes to the border, as NumPy's fmax/fmin do.
    col = torch.nan_to_num(col, nan=0.0).clamp_(0.0, float(field.width - 1))
    row = torch.nan_to_num(row, nan=0.0).clamp_(0.0, float(field.height - 1))
    flat = row.to(torch.int64) * field.width + col.to(torch.int64)
    return field.padded[flat]


def device_blocks(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike
            ) -> tuple[_DeviceField, Any, Any]:
    """The field on its device, the poses in grid units (N, 3, float64) and the end points in cell units (B, 2,
    float32) there."""
    torch = import_torch()
    device = dist_field.torch_device
    if device is None:
        raise ValueError("the distance field has no torch_device")
    grid = dist_field.to_grid(np.asarray(pose, dtype=np.float64).reshape(-1, 3))
    cells = (np.asarray(points_base, dtype=np.float64).reshape(-1, 2) / dist_field.resolution_m).astype(np.float32)
    return (_device_field(dist_field, device), torch.from_numpy(grid).to(device),
            torch.from_numpy(cells).to(device))


def endpoint_distances(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike) -> Float32Array:
    """(N, B) float32 field distances of every beam end point of every particle, computed on the field's
    ``torch_device`` (:func:`~.likelihood_field.endpoint_distances`)."""
    field, grid, cells = device_blocks(dist_field, pose, points_base)
    out = np.empty((grid.shape[0], cells.shape[0]), dtype=np.float32)
    for start in range(0, grid.shape[0], BLOCK_PARTICLES):
        stop = min(start + BLOCK_PARTICLES, grid.shape[0])
        out[start:stop] = block_distances(field, grid[start:stop], cells).cpu().numpy()
    return out


def _beam_likelihood(d: Any, z_hit: float, z_rand: float, sigma_hit: float, max_range: float) -> Any:
    """pz = z_hit·exp(−d²/2σ²) + z_rand/max_range, in place of ``d`` (float32), in
    :func:`~.likelihood_field.beam_likelihood`'s order."""
    torch = import_torch()
    pz = d.mul_(d)
    pz *= float(np.float32(-0.5 / (sigma_hit * sigma_hit)))
    pz = torch.exp_(pz)
    pz *= float(np.float32(z_hit))
    pz += float(np.float32(z_rand / max_range))
    return pz


def _combine_beams(pz: Any, combination: BeamCombination) -> Any:
    """(n,) float64 log-likelihoods of (n, B) pz (:func:`~.likelihood_field.combine_beams`)."""
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination

    torch = import_torch()
    if combination is BeamCombination.AMCL:
        return torch.log1p((pz * pz * pz).sum(dim=1, dtype=torch.float64))
    return torch.log(pz).sum(dim=1, dtype=torch.float64)


def field_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike, z_hit: float,
                         z_rand: float, sigma_hit: float, max_range: float, combination: BeamCombination
                         ) -> FloatArray:
    """log p(z | x) (N,) of each particle, fused on the field's ``torch_device``
    (:func:`~.likelihood_field.field_log_likelihood`): pz = z_hit·exp(−d²/2σ²) + z_rand/max_range per beam in
    float32, then log(1 + Σ pz³) (AMCL) or Σ log pz (PRODUCT) summed in float64."""
    field, grid, cells = device_blocks(dist_field, pose, points_base)
    out = np.zeros(grid.shape[0])
    if cells.shape[0] == 0:
        return out
    for start in range(0, grid.shape[0], BLOCK_PARTICLES):
        stop = min(start + BLOCK_PARTICLES, grid.shape[0])
        pz = _beam_likelihood(block_distances(field, grid[start:stop], cells), z_hit, z_rand, sigma_hit, max_range)
        out[start:stop] = _combine_beams(pz, combination).cpu().numpy()
    return out


def _support_weights(pz: Any, weight: Any, floor: float, combination: BeamCombination) -> Any:
    """Per beam, the particles' posterior weight (N, B) given the other beams, each pz clipped at ``floor``
    (:func:`~.likelihood_field.beam_support_weights`, float32 in its order); ``weight`` (N,) float64."""
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination

    torch = import_torch()
    p = torch.fmax(pz, torch.tensor(float(np.float32(floor)), dtype=torch.float32, device=pz.device))
    log_w = torch.log(weight).float()[:, None]
    if combination is BeamCombination.AMCL:
        cubed = p * p * p
        log_post = torch.log1p(cubed.sum(dim=1, keepdim=True) - cubed)
    else:
        log_post = torch.log_(p)
        log_post = log_post.sum(dim=1, keepdim=True) - log_post
    log_post += log_w
    log_post -= log_post.max(dim=0, keepdim=True).values
    post = torch.exp_(log_post)
    post /= post.sum(dim=0, keepdim=True)
    return post


def skipped_field_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, weight: npt.ArrayLike,
                                 points_base: npt.ArrayLike, config: LocalizeConfig, range_max_m: float,
                                 combination: BeamCombination) -> tuple[FloatArray, int]:
    """log p(z | x) (N,) with beam skipping, and the number of beams skipped, every step on the field's ``torch_device``
    (:func:`~.likelihood_field.skipped_field_log_likelihood`): the (N, B) likelihoods, the support each beam has
    (:func:`~.likelihood_field.beam_support_weights`), the skip mask (:func:`~.likelihood_field.beam_skip_mask`)
    and the sum stay there; N log-likelihoods come back. The whole cloud is one block (the support of a beam
    is normalized over all particles): (N, B) float32, 12 MB at 50,000 particles and 60 beams."""
    field, grid, cells = device_blocks(dist_field, pose, points_base)
    if cells.shape[0] == 0:
        return np.zeros(grid.shape[0]), 0
    pz = _beam_likelihood(block_distances(field, grid, cells), config.z_hit, config.z_rand, config.sigma_hit,
                          range_max_m)
    loglik, skipped = skip_and_combine(pz, pose, weight, config, range_max_m, combination)
    return np.asarray(loglik.cpu().numpy()), skipped


def skip_and_combine(pz: Any, pose: npt.ArrayLike, weight: npt.ArrayLike, config: LocalizeConfig,
                     range_max_m: float, combination: BeamCombination) -> tuple[Any, int]:
    """(N,) float64 log-likelihoods on the device of (N, B) float32 per-beam likelihoods there, with beam skipping
    (:func:`~.likelihood_field.skip_unexplained`, then :func:`~.likelihood_field.combine_beams`); ``pz`` is
    changed in place. The number of beams skipped."""
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination, beam_skip_floor, cloud_converged

    torch = import_torch()
    skipped = 0
    if config.do_beamskip and cloud_converged(weight, pose, config):  # as skip_unexplained: a converged cloud only
        floor = beam_skip_floor(config, range_max_m)
        explained = pz >= float(np.float32(floor))
        if config.beam_skip_support == "particles":  # nav2_amcl: the share of the particles
            support = torch.ones((pz.shape[0], 1), dtype=torch.float32, device=pz.device)
        else:
            w = torch.as_tensor(np.ascontiguousarray(weight, dtype=np.float64).reshape(-1), device=pz.device)
            support = _support_weights(pz, w, floor, combination)
        share = (torch.where(explained, support, 0.0).sum(dim=0, dtype=torch.float64)
                 / support.sum(dim=0, dtype=torch.float64).clamp_min(1e-300))
        skip = share < config.beam_skip_threshold
        neutral = 1.0 if combination is BeamCombination.PRODUCT else 0.0
        skipped = int(skip.sum().item())
        if skipped / skip.shape[0] > config.beam_skip_error_threshold:  # lost: nothing skipped (beam_skip_mask)
            skipped = 0
        elif skipped:
            pz[:, skip] = neutral
        pz[torch.isnan(pz)] = neutral
    return _combine_beams(pz, combination), skipped
