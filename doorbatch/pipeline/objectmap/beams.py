"""The measurements of paper 001 Sec. III as flat arrays: every kept beam of every pass in the map frame.

Beam k of scan t: origin o (the laser in the map frame), unit direction u, range d (a no-return beam or a
range ≥ dmax reads d = dmax: the virtual object at the max-range mark), its end point π = o + d·u
(eq. 2) and its colour l (NaN when the beam has none).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.geometry.se2 import rotation_matrix

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

# Beams per block of the per-beam steps that allocate several temporaries per beam (E-step, eq. (9) gains):
# their scratch memory stays ~100 MB however long the log, while the results are the same to the bit.
BEAM_BLOCK = 1 << 18


def beam_blocks(n: int, size: int | None = None) -> Iterator[slice]:
    """Consecutive slices covering range(n), each at most ``size`` (default ``BEAM_BLOCK``) long."""
    size = size or BEAM_BLOCK
    for start in range(0, n, size):
        yield slice(start, min(n, start + size))


@dataclass(frozen=True)
class BeamSet:
    """N beams. ``hit`` marks beams that returned within (0, dmax); ``color`` is (N, 3), NaN without colour."""

    pass_index: IntArray
    origin: FloatArray  # (N, 2)
    direction: FloatArray  # (N, 2) unit
    range_m: FloatArray  # (N,) ≤ dmax
    dmax: FloatArray  # (N,)
    hit: BoolArray
    color: FloatArray  # (N, 3)
    n_passes: int

    def __len__(self) -> int:
        return int(self.range_m.shape[0])

    @property
    def points(self) -> FloatArray:
        """π of eq. (2) for every beam (the max-range mark for no-return beams)."""
        return self.origin + self.range_m[:, None] * self.direction

    @property
    def has_color(self) -> bool:
        return bool(np.isfinite(self.color[:, 0]).any())

    def subset(self, keep: BoolArray | IntArray | slice) -> BeamSet:
        """The beams ``keep`` (a slice gives views, no copy)."""
        return BeamSet(self.pass_index[keep], self.origin[keep], self.direction[keep], self.range_m[keep],
                       self.dmax[keep], self.hit[keep], self.color[keep], self.n_passes)



@dataclass(frozen=True)
class ScanBeams:
    """One scan's beams in base_link: laser pose (x, y, yaw of the 2×3 affine), beam angles, ranges."""

    pose: FloatArray  # (3,) base_link in the map frame
    laser_to_base: FloatArray  # (2, 3)
    angles: FloatArray  # (B,) in the laser frame
    ranges: FloatArray  # (B,)
    range_min: float
    range_max: float
    colors: FloatArray | None  # (B, 3) or None


def beams_from_scans(passes: Sequence[Sequence[ScanBeams]], max_range_m: float, beam_stride: int = 1) -> BeamSet:
    """Flatten scans (one list per pass) into a :class:`BeamSet`.

    NaN ranges and ranges below range_min carry no information and are dropped; +inf and ranges at or
    beyond dmax = min(range_max, ``max_range_m``) become max-range readings (paper 001 Sec. III).
    """
    parts: list[tuple[int, FloatArray, FloatArray, FloatArray, FloatArray, BoolArray, FloatArray]] = []
    for t, scans in enumerate(passes):
        for sc in scans:
            idx = np.arange(0, sc.ranges.shape[0], beam_stride)
            r = sc.ranges[idx].astype(np.float64)
            dmax = min(sc.range_max, max_range_m)
            keep = ~np.isnan(r) & (r >= sc.range_min)
            idx, r = idx[keep], r[keep]
            hit = r < dmax
            r = np.where(hit, r, dmax)
            rot = rotation_matrix(sc.pose[2])
            lin = rot @ sc.laser_to_base[:, :2]
            origin = rot @ sc.laser_to_base[:, 2] + sc.pose[:2]
            local = np.stack([np.cos(sc.angles[idx]), np.sin(sc.angles[idx])], axis=1)
            dirs = local @ lin.T
            dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
            col = np.full((idx.shape[0], 3), np.nan)
            if sc.colors is not None and sc.colors.shape[0] == sc.ranges.shape[0]:
                col = sc.colors[idx].astype(np.float64)
                col[~hit] = np.nan
            parts.append((t, np.broadcast_to(origin, (idx.shape[0], 2)), dirs, r, np.full(idx.shape[0], dmax),
                          hit, col))
    if not parts:
        z = np.zeros(0)
        return BeamSet(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros((0, 2)), z, z,
                       np.zeros(0, dtype=bool), np.zeros((0, 3)), len(passes))
    return BeamSet(
        pass_index=np.concatenate([np.full(p[3].shape[0], p[0], dtype=np.int64) for p in parts]),
        origin=np.concatenate([p[1] for p in parts]),
        direction=np.concatenate([p[2] for p in parts]),
        range_m=np.concatenate([p[3] for p in parts]),
        dmax=np.concatenate([p[4] for p in parts]),
        hit=np.concatenate([p[5] for p in parts]),
        color=np.concatenate([p[6] for p in parts]),
        n_passes=len(passes),
    )
