"""The likelihood field's hot loop in torch: the optional backend of issue #5, item 5 (``localize.backend: torch``).

Same interface, same arithmetic as :func:`~.likelihood_field.endpoint_distances` and
:func:`~.likelihood_field.field_log_likelihood`, on a torch device: particle poses go to the grid frame in
float64 (:meth:`~.likelihood_field.DistanceField.to_grid`), cos/sin are rounded to float32, and every beam end
point is moved, clamped into the padded field and truncated to its cell in float32, one elementwise operation at
a time in NumPy's order, so the cells looked up are NumPy's (a last-ulp difference of a cosine between libraries
can move an end point lying on a cell border to the neighbouring cell; the tests bound how often).

The padded field goes to the device once per :class:`~.likelihood_field.DistanceField` and stays there. Each call
sends the poses (N × 3 float64) and the end points (B × 2) and brings back the (N, B) distances or, fused, only the
(N,) log-likelihoods. Where it pays: on a GPU; on a CPU NumPy is faster (docs/benchmarks.md).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from doorbatch.errors import OptionalDependencyError, UsageError

if TYPE_CHECKING:
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination, DistanceField

FloatArray = npt.NDArray[np.float64]
Float32Array = npt.NDArray[np.float32]
# Particles per block: (block × B) float32 temporaries, ~16 MB each at 60 beams; bounds device memory for any N.
BLOCK_PARTICLES = 65536


def _torch() -> Any:
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
    torch = _torch()
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
    torch = _torch()
    padded = torch.from_numpy(np.ascontiguousarray(dist_field.padded).ravel()).to(device)
    made = _DeviceField(padded, dist_field.width + 2, dist_field.height + 2)
    dist_field.device_cache[device] = made
    return made


def _block_distances(field: _DeviceField, grid: Any, cells: Any) -> Any:
    """(n, B) float32 distances for grid-frame poses (n, 3, float64) and end points in cell units (B, 2, float32),
    in the order of ``likelihood_field._chunk_distances`` and ``_gather``."""
    torch = _torch()
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


def _blocks(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike
            ) -> tuple[_DeviceField, Any, Any]:
    """The field on its device, the poses in grid units (N, 3, float64) and the end points in cell units (B, 2,
    float32) there."""
    torch = _torch()
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
    field, grid, cells = _blocks(dist_field, pose, points_base)
    out = np.empty((grid.shape[0], cells.shape[0]), dtype=np.float32)
    for start in range(0, grid.shape[0], BLOCK_PARTICLES):
        stop = min(start + BLOCK_PARTICLES, grid.shape[0])
        out[start:stop] = _block_distances(field, grid[start:stop], cells).cpu().numpy()
    return out


def field_log_likelihood(dist_field: DistanceField, pose: npt.ArrayLike, points_base: npt.ArrayLike, z_hit: float,
                         z_rand: float, sigma_hit: float, max_range: float, combination: BeamCombination
                         ) -> FloatArray:
    """log p(z | x) (N,) of each particle, fused on the field's ``torch_device``
    (:func:`~.likelihood_field.field_log_likelihood`): pz = z_hit·exp(−d²/2σ²) + z_rand/max_range per beam in
    float32, then log(1 + Σ pz³) (AMCL) or Σ log pz (PRODUCT) summed in float64."""
    from doorbatch.pipeline.localize.likelihood_field import BeamCombination

    torch = _torch()
    field, grid, cells = _blocks(dist_field, pose, points_base)
    out = np.zeros(grid.shape[0])
    if cells.shape[0] == 0:
        return out
    for start in range(0, grid.shape[0], BLOCK_PARTICLES):
        stop = min(start + BLOCK_PARTICLES, grid.shape[0])
        d = _block_distances(field, grid[start:stop], cells)
        pz = d * d
        pz *= float(np.float32(-0.5 / (sigma_hit * sigma_hit)))
        pz = torch.exp(pz)
        pz *= float(np.float32(z_hit))
        pz += float(np.float32(z_rand / max_range))
        if combination is BeamCombination.AMCL:
            ll = torch.log1p((pz * pz * pz).sum(dim=1, dtype=torch.float64))
        else:
            ll = torch.log(pz).sum(dim=1, dtype=torch.float64)
        out[start:stop] = ll.cpu().numpy()
    return out
