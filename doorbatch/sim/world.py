"""Simulated worlds: walls, rooms, pillars, niches and hinged doors, parsed from YAML into arrays.

A world file (``configs/worlds/*.yaml``) is validated by the pydantic models below (``extra="forbid"``
everywhere, so a typo is an error with its key path) and converted into :class:`World`, a frozen dataclass
of NumPy arrays that the ray caster and the sensors use.

Geometry conventions (map frame, metres, radians internally; the YAML gives angles in degrees):

* A door is a leaf of length L turning about its hinge h. At opening angle α ≥ 0 its free end is
  ``h + L·(cos φ, sin φ)`` with ``φ = closed_yaw + s·α``, where ``closed_yaw`` is the global direction
  hinge→free end of the closed leaf and ``s = opening_sign`` (+1: the leaf opens counter-clockwise).
  The signed angle that ``doors.parquet`` and the truth file use is ``s·α`` (CCW positive).
* A closed door is flush with its wall: the wall segments that are collinear with a closed leaf are cut
  where the leaf lies (and where a niche opens), so an open door leaves a gap in the wall.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
import numpy.typing as npt
import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from doorbatch.errors import ConfigError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

Point = tuple[float, float]
RGB = tuple[
    Annotated[float, Field(ge=0, le=255)], Annotated[float, Field(ge=0, le=255)], Annotated[float, Field(ge=0, le=255)]
]
RGBStd = tuple[Annotated[float, Field(ge=0)], Annotated[float, Field(ge=0)], Annotated[float, Field(ge=0)]]

# Two points closer than this (m) are the same point; a wall is collinear with a door leaf within it.
GEOMETRY_TOLERANCE_M = 1e-6


class SurfaceKind(IntEnum):
    """What a static segment belongs to (kept per segment so sensors and maps can tell them apart)."""

    WALL = 0
    ROOM = 1
    PILLAR = 2
    NICHE = 3


# --------------------------------------------------------------------------------------------- YAML models


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class MaterialSpec(_Model):
    """A surface color model: per-channel Gaussian N(mean_rgb, std_rgb²), 0..255."""

    mean_rgb: RGB
    std_rgb: RGBStd = (0.0, 0.0, 0.0)


class PolylineSpec(_Model):
    """A chain of wall segments through ``points_m`` (closed: back to the first point)."""

    name: str = ""
    points_m: list[Point] = Field(min_length=2)
    closed: bool = False
    material: str = "wall"


class PillarSpec(_Model):
    """A rectangular pillar (four segments) centred at ``center_m``, ``size_m`` = (along x, along y)."""

    name: str = ""
    center_m: Point
    size_m: tuple[Annotated[float, Field(gt=0)], Annotated[float, Field(gt=0)]]
    yaw_deg: float = 0.0
    material: str = "pillar"


class NicheSpec(_Model):
    """A rectangular recess: the wall between ``start_m`` and ``end_m`` is cut and a U of depth ``depth_m``
    is added on ``side`` (left or right of start→end)."""

    name: str = ""
    start_m: Point
    end_m: Point
    depth_m: float = Field(gt=0)
    side: Literal["left", "right"]
    material: str = "wall"


class HandleSpec(_Model):
    """A handle on both faces of a leaf: centre ``height_m`` above the floor and ``from_free_end_m`` from
    the free end along the leaf; ``size_m`` = (width along the leaf, height)."""

    height_m: float = Field(1.0, gt=0)
    from_free_end_m: float = Field(0.08, ge=0)
    size_m: tuple[Annotated[float, Field(gt=0)], Annotated[float, Field(gt=0)]] = (0.14, 0.05)
    material: str = "handle"


class DoorSpec(_Model):
    """One hinged door leaf (see the module docstring for the angle convention)."""

    name: str
    hinge_m: Point
    length_m: float = Field(gt=0)
    closed_yaw_deg: float
    opening_sign: Literal[-1, 1]
    max_angle_deg: float = Field(gt=0, le=180)
    height_m: float = Field(2.0, gt=0)
    material: str = "door"
    handle: HandleSpec | None = HandleSpec()


class RouteSpec(_Model):
    """A named polyline that scenarios drive (robot) or walk (people) along. ``through_doors``: doors the
    route passes through; a pass that uses the route holds them fully open."""

    points_m: list[Point] = Field(min_length=2)
    through_doors: list[str] = []


class WorldSpec(_Model):
    """A whole world file."""

    name: str
    description: str = ""
    wall_height_m: float = Field(2.6, gt=0)
    floor_rgb: RGB = (120.0, 115.0, 105.0)
    ceiling_rgb: RGB = (235.0, 235.0, 230.0)
    materials: dict[str, MaterialSpec]
    walls: list[PolylineSpec] = Field(min_length=1)
    rooms: list[PolylineSpec] = []
    pillars: list[PillarSpec] = []
    niches: list[NicheSpec] = []
    doors: list[DoorSpec] = []
    routes: dict[str, RouteSpec] = {}

    @model_validator(mode="after")
    def _check_references(self) -> WorldSpec:
        used = [w.material for w in (*self.walls, *self.rooms)] + [p.material for p in self.pillars]
        used += [n.material for n in self.niches]
        used += [d.material for d in self.doors] + [d.handle.material for d in self.doors if d.handle]
        missing = sorted({m for m in used if m not in self.materials})
        if missing:
            raise ValueError(f"materials {missing} are used but not defined under materials")
        names = [d.name for d in self.doors]
        if len(set(names)) != len(names):
            raise ValueError("door names must be unique")
        for route_name, route in self.routes.items():
            unknown = [d for d in route.through_doors if d not in names]
            if unknown:
                raise ValueError(f"route {route_name!r}: through_doors names unknown doors {unknown}")
        return self


# --------------------------------------------------------------------------------------------- arrays


@dataclass(frozen=True)
class Doors:
    """D door leaves as arrays (angles in radians, lengths in metres, colors 0..255)."""

    names: tuple[str, ...]
    hinge_xy: FloatArray  # (D, 2)
    length_m: FloatArray  # (D,)
    closed_yaw_rad: FloatArray  # (D,) direction hinge→free end of the closed leaf
    opening_sign: FloatArray  # (D,) +1: opens counter-clockwise
    max_angle_rad: FloatArray  # (D,)
    height_m: FloatArray  # (D,)
    color_mean_rgb: FloatArray  # (D, 3)
    color_std_rgb: FloatArray  # (D, 3)
    has_handle: npt.NDArray[np.bool_]  # (D,)
    handle_height_m: FloatArray  # (D,)
    handle_from_free_end_m: FloatArray  # (D,)
    handle_size_m: FloatArray  # (D, 2) width along the leaf, height
    handle_rgb: FloatArray  # (D, 3)

    @property
    def count(self) -> int:
        """Number of doors."""
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of the door called ``name``.

        Raises:
            ConfigError: no such door.
        """
        try:
            return self.names.index(name)
        except ValueError:
            raise ConfigError(f"no door named {name!r} (doors: {', '.join(self.names)})") from None


@dataclass(frozen=True)
class Route:
    """A named polyline (N, 2) and the doors it passes through (indices into :class:`Doors`)."""

    points_m: FloatArray
    through_doors: tuple[int, ...] = ()


@dataclass(frozen=True)
class World:
    """A world as arrays: static segments (after door and niche cuts) with their color models, and doors."""

    name: str
    segments: FloatArray  # (N, 2, 2) static segments [[x0, y0], [x1, y1]]
    segment_kind: npt.NDArray[np.int8]  # (N,) SurfaceKind
    segment_color_mean: FloatArray  # (N, 3)
    segment_color_std: FloatArray  # (N, 3)
    doors: Doors
    wall_height_m: float
    wall_rgb: FloatArray  # (3,) the "wall" material: lintels above doors in the camera image
    floor_rgb: FloatArray  # (3,)
    ceiling_rgb: FloatArray  # (3,)
    routes: dict[str, Route] = field(default_factory=dict)

    def route(self, name: str) -> Route:
        """The route called ``name``.

        Raises:
            ConfigError: no such route.
        """
        if name not in self.routes:
            raise ConfigError(f"world {self.name!r} has no route {name!r} (routes: {', '.join(self.routes)})")
        return self.routes[name]


# --------------------------------------------------------------------------------------------- geometry


def door_leaf_segments(world: World | Doors, angles_rad: npt.ArrayLike) -> FloatArray:
    """Leaf segments [hinge, free end] of a world's doors at opening angles α (radians, ≥ 0; (D,) or (T, D)).

    free end = h + L·(cos φ, sin φ), φ = closed_yaw + opening_sign·α. Returns (..., D, 2, 2).
    """
    doors = world.doors if isinstance(world, World) else world
    alpha = np.asarray(angles_rad, dtype=np.float64)
    phi = doors.closed_yaw_rad + doors.opening_sign * alpha
    free = doors.hinge_xy + doors.length_m[..., None] * np.stack([np.cos(phi), np.sin(phi)], axis=-1)
    hinge = np.broadcast_to(doors.hinge_xy, free.shape)
    return np.stack([hinge, free], axis=-2)


def _polyline_segments(points: FloatArray, closed: bool) -> FloatArray:
    pts = np.vstack([points, points[:1]]) if closed else points
    return np.stack([pts[:-1], pts[1:]], axis=1)


def _rectangle(center: Point, size: tuple[float, float], yaw: float) -> FloatArray:
    hx, hy = size[0] / 2, size[1] / 2
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    c, s = math.cos(yaw), math.sin(yaw)
    return np.asarray(corners @ np.array([[c, s], [-s, c]]) + np.asarray(center), dtype=np.float64)


def cut_segments(segments: FloatArray, openings: FloatArray) -> tuple[FloatArray, IntArray]:
    """Remove from each segment the parts covered by collinear openings (door footprints, niche mouths).

    A segment a→b is cut by an opening p→q when both p and q lie on the line through a, b (within
    :data:`GEOMETRY_TOLERANCE_M`); the interval of u ∈ [0, 1] (point a + u·(b − a)) between the projections
    of p and q is removed. Returns the remaining pieces and, for each, the index of its source segment.
    World construction only (tens of segments), so a plain loop is fine here.
    """
    pieces: list[FloatArray] = []
    source: list[int] = []
    for i, (a, b) in enumerate(segments):
        e = b - a
        length = float(np.hypot(*e))
        kept = [(0.0, 1.0)]
        for p, q in openings:
            dist_p = abs(e[0] * (p[1] - a[1]) - e[1] * (p[0] - a[0])) / length
            dist_q = abs(e[0] * (q[1] - a[1]) - e[1] * (q[0] - a[0])) / length
            if dist_p > GEOMETRY_TOLERANCE_M or dist_q > GEOMETRY_TOLERANCE_M:
                continue
            u0, u1 = sorted((float(np.dot(p - a, e)) / length**2, float(np.dot(q - a, e)) / length**2))
            new: list[tuple[float, float]] = []
            for lo, hi in kept:
                if u1 <= lo or u0 >= hi:
                    new.append((lo, hi))
                    continue
                if u0 > lo:
                    new.append((lo, u0))
                if u1 < hi:
                    new.append((u1, hi))
            kept = new
        for lo, hi in kept:
            if (hi - lo) * length > GEOMETRY_TOLERANCE_M:
                # rounded to 1 nm so that a cut ends exactly where the door's hinge or free end is
                pieces.append(np.round(np.stack([a + lo * e, a + hi * e]), 9))
                source.append(i)
    if not pieces:
        return np.zeros((0, 2, 2)), np.zeros(0, dtype=np.int64)
    return np.stack(pieces), np.asarray(source, dtype=np.int64)


# --------------------------------------------------------------------------------------------- building


def build_world(spec: WorldSpec) -> World:
    """Convert a validated :class:`WorldSpec` into arrays (degrees → radians, door and niche cuts)."""
    mats = spec.materials
    raw: list[FloatArray] = []
    kinds: list[int] = []
    material: list[str] = []

    def add(segs: FloatArray, kind: SurfaceKind, mat: str) -> None:
        raw.append(segs)
        kinds.extend([int(kind)] * segs.shape[0])
        material.extend([mat] * segs.shape[0])

    for wall in spec.walls:
        add(_polyline_segments(np.asarray(wall.points_m, dtype=np.float64), wall.closed), SurfaceKind.WALL,
            wall.material)
    for room in spec.rooms:
        add(_polyline_segments(np.asarray(room.points_m, dtype=np.float64), room.closed), SurfaceKind.ROOM,
            room.material)
    cuttable = np.concatenate(raw) if raw else np.zeros((0, 2, 2))
    doors = _build_doors(spec)
    openings = [door_leaf_segments(doors, np.zeros(doors.count))] if doors.count else []
    niche_segs: list[FloatArray] = []
    for niche in spec.niches:
        p, q = np.asarray(niche.start_m, dtype=np.float64), np.asarray(niche.end_m, dtype=np.float64)
        openings.append(np.stack([p, q])[None])
        d = (q - p) / np.hypot(*(q - p))
        normal = np.array([-d[1], d[0]]) * (1.0 if niche.side == "left" else -1.0) * niche.depth_m
        niche_segs.append(_polyline_segments(np.stack([p, p + normal, q + normal, q]), closed=False))
    cut, src = cut_segments(cuttable, np.concatenate(openings) if openings else np.zeros((0, 2, 2)))
    segments = [cut]
    seg_kind = [np.asarray(kinds, dtype=np.int8)[src]]
    seg_mat = [material[i] for i in src]
    for niche, segs in zip(spec.niches, niche_segs, strict=True):
        segments.append(segs)
        seg_kind.append(np.full(segs.shape[0], SurfaceKind.NICHE, dtype=np.int8))
        seg_mat += [niche.material] * segs.shape[0]
    for pillar in spec.pillars:
        segs = _polyline_segments(_rectangle(pillar.center_m, pillar.size_m, math.radians(pillar.yaw_deg)), True)
        segments.append(segs)
        seg_kind.append(np.full(4, SurfaceKind.PILLAR, dtype=np.int8))
        seg_mat += [pillar.material] * 4
    routes = {
        name: Route(np.asarray(r.points_m, dtype=np.float64), tuple(doors.index(d) for d in r.through_doors))
        for name, r in spec.routes.items()
    }
    wall_rgb = mats["wall"].mean_rgb if "wall" in mats else (200.0, 200.0, 200.0)
    return World(
        name=spec.name,
        segments=np.concatenate(segments),
        segment_kind=np.concatenate(seg_kind),
        segment_color_mean=np.array([mats[m].mean_rgb for m in seg_mat], dtype=np.float64).reshape(-1, 3),
        segment_color_std=np.array([mats[m].std_rgb for m in seg_mat], dtype=np.float64).reshape(-1, 3),
        doors=doors,
        wall_height_m=spec.wall_height_m,
        wall_rgb=np.asarray(wall_rgb, dtype=np.float64),
        floor_rgb=np.asarray(spec.floor_rgb, dtype=np.float64),
        ceiling_rgb=np.asarray(spec.ceiling_rgb, dtype=np.float64),
        routes=routes,
    )


def _build_doors(spec: WorldSpec) -> Doors:
    ds = spec.doors
    mats = spec.materials

    def arr(values: Sequence[float] | Sequence[tuple[float, ...]], cols: int = 0) -> FloatArray:
        out = np.asarray(values, dtype=np.float64)
        return out.reshape(-1, cols) if cols else out.reshape(-1)

    handles = [d.handle or HandleSpec() for d in ds]
    return Doors(
        names=tuple(d.name for d in ds),
        hinge_xy=arr([d.hinge_m for d in ds], 2),
        length_m=arr([d.length_m for d in ds]),
        closed_yaw_rad=np.radians(arr([d.closed_yaw_deg for d in ds])),
        opening_sign=arr([float(d.opening_sign) for d in ds]),
        max_angle_rad=np.radians(arr([d.max_angle_deg for d in ds])),
        height_m=arr([d.height_m for d in ds]),
        color_mean_rgb=arr([mats[d.material].mean_rgb for d in ds], 3),
        color_std_rgb=arr([mats[d.material].std_rgb for d in ds], 3),
        has_handle=np.array([d.handle is not None for d in ds], dtype=bool),
        handle_height_m=arr([h.height_m for h in handles]),
        handle_from_free_end_m=arr([h.from_free_end_m for h in handles]),
        handle_size_m=arr([h.size_m for h in handles], 2),
        handle_rgb=arr([mats[h.material].mean_rgb if h.material in mats else (40.0, 40.0, 40.0)
                        for h in handles], 3),
    )


def parse_world(data: object, source: str = "world") -> World:
    """Validate a world mapping (as loaded from YAML) and build it.

    Raises:
        ConfigError: unknown key, wrong type or value, or a dangling reference, with the key path.
    """
    try:
        spec = WorldSpec.model_validate(data)
    except ValidationError as err:
        raise ConfigError(f"{source}: {explain_validation(err)}") from err
    return build_world(spec)


def load_world(path: Path) -> World:
    """Read and build a world YAML file.

    Raises:
        ConfigError: unreadable file, bad YAML, or an invalid world.
    """
    return parse_world(read_yaml(path), str(path))


def read_yaml(path: Path) -> object:
    """The content of a YAML file.

    Raises:
        ConfigError: the file cannot be read or is not YAML.
    """
    try:
        return yaml.safe_load(Path(path).read_text())
    except OSError as err:
        raise ConfigError(f"{path}: cannot read: {err.strerror or err}") from err
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: not valid YAML: {err}") from err


def explain_validation(err: ValidationError) -> str:
    """One line for the first problem pydantic found, with its key path."""
    first = err.errors()[0]
    key = ".".join(str(p) for p in first["loc"]) or "(top level)"
    if first["type"] == "extra_forbidden":
        return f"unknown key {key!r}"
    return f"key {key!r}: {first['msg']}"
