"""The object map of paper 001 Sec. II: walls (a line with collinear segments), doors (hinge, width, one
angle per pass) and the global class parameters (door width, class colours).

A wall is the line n·p = β (``normal`` n, unit; ``offset`` β) with segments given by their end points'
coordinates s = τ·p along the tangent τ = (−n_y, n_x): 2·|S_W| + 2 parameters (Sec. II). A door is a
leaf of width w turning about its hinge h; in pass t its free end is h + w·(cos ψ_t, sin ψ_t), ψ_t the
leaf's global direction (the paper's ψ relative to a reference direction; we keep it global).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

WALL, DOOR = 0, 1  # class indices


@dataclass(frozen=True)
class Wall:
    """A line n·p = β with segments [s0, s1] along τ = (−n_y, n_x)."""

    normal: FloatArray  # (2,)
    offset: float
    segments: FloatArray  # (K, 2), s0 < s1, sorted

    @property
    def tangent(self) -> FloatArray:
        return np.array([-self.normal[1], self.normal[0]])

    def endpoints(self) -> FloatArray:
        """(K, 2, 2) segment end points in the map frame."""
        base = self.offset * self.normal
        return base + self.segments[:, :, None] * self.tangent

    @property
    def length(self) -> float:
        return float(np.sum(self.segments[:, 1] - self.segments[:, 0])) if self.segments.size else 0.0


@dataclass(frozen=True)
class Door:
    """A hinged leaf: ``hinge`` (2,), ``yaws`` (P,) the leaf direction in each pass; ``width`` is used only
    when widths are per door (else the class width applies)."""

    hinge: FloatArray
    yaws: FloatArray
    width: float | None = None


@dataclass(frozen=True)
class ClassParams:
    """Global class parameters (Sec. II): the door width and a Gaussian colour (mean, per-channel variance)
    per class, index 0 walls and 1 doors. ``has_color`` is false for a range-only model."""

    door_width_m: float
    color_mean: FloatArray = field(default_factory=lambda: np.zeros((2, 3)))  # (2, 3) RGB
    color_var: FloatArray = field(default_factory=lambda: np.full((2, 3), 400.0))
    has_color: bool = False
    # A door class per paint (em.door_color_components > 1): the door colours' mixture weights (M,), means
    # and per-channel variances (M, 3); empty: the door colour is the one Gaussian of index 1 (paper 001).
    door_mix_weight: FloatArray = field(default_factory=lambda: np.zeros(0))
    door_mix_mean: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))
    door_mix_var: FloatArray = field(default_factory=lambda: np.zeros((0, 3)))

    def with_width(self, width: float) -> ClassParams:
        return replace(self, door_width_m=float(width))


@dataclass(frozen=True)
class ObjectMap:
    """Walls, doors and class parameters for ``n_passes`` passes."""

    walls: list[Wall]
    doors: list[Door]
    classes: ClassParams
    n_passes: int

    def door_width(self, i: int) -> float:
        w = self.doors[i].width
        return self.classes.door_width_m if w is None else w

    def segments(self, pass_index: int) -> tuple[FloatArray, IntArray, IntArray]:
        """All segments in pass ``pass_index``: (S, 2, 2) end points, (S,) class (doors first, so that a
        door flush with a wall is the first object on ties), (S,) index of the object in its class list."""
        segs: list[FloatArray] = []
        cls: list[int] = []
        obj: list[int] = []
        for i, d in enumerate(self.doors):
            yaw = d.yaws[pass_index]
            end = d.hinge + self.door_width(i) * np.array([np.cos(yaw), np.sin(yaw)])
            segs.append(np.stack([d.hinge, end])[None])
            cls.append(DOOR)
            obj.append(i)
        for j, w in enumerate(self.walls):
            if w.segments.size:
                segs.append(w.endpoints())
                cls += [WALL] * w.segments.shape[0]
                obj += [j] * w.segments.shape[0]
        if not segs:
            return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return np.concatenate(segs), np.array(cls, dtype=np.int64), np.array(obj, dtype=np.int64)

    def total_length(self) -> float:
        """L[M]: the length of all segments (walls and door leaves)."""
        return sum(w.length for w in self.walls) + sum(self.door_width(i) for i in range(len(self.doors)))
