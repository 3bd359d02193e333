"""The simulator's truth file (``<log stem>.truth.yaml``): the world, door angles over time, passes.

Written next to every simulated log by :func:`doorbatch.sim.simulate.run_simulation`; read by evaluation
(and by anyone else) with :func:`read_truth`. SI units, map frame, angles in radians. Layout (exact keys)::

    format: doorbatch-sim-truth/1
    generator: {doorbatch_version, world, world_file, scenario, scenario_file, seed}
    frame_id: map
    start_ns, end_ns                 # int, header stamps of the first and last message
    files: {log, trajectory, map_closed, map_static}   # names relative to this file's folder
    world:
      name, wall_height_m
      segments: [[x0, y0, x1, y1], ...]                # static segments (door leaves excluded)
      segment_kinds: [wall | room | pillar | niche, ...]
      doors: [{door_id, name, hinge_x, hinge_y, length, closed_yaw, opening_sign, max_angle, height,
               color_mean_rgb, color_std_rgb, handle: null | {height, from_free_end, width, size_z}}]
    passes: [{index, name, begin_ns, stationary_ns, end_ns}]
    door_angles:                     # knots of piecewise-linear angles; constant before the first knot
      columns: [stamp_ns, door_id, angle]   # and after the last; angle = opening_sign · opening (CCW +)
      rows: [[stamp_ns, door_id, angle], ...]           # sorted by door_id, then stamp_ns
    leaf_observations:               # per pass (stationary interval) and door: laser returns on the leaf,
      columns: [pass, door_id, laser_hits, scans_seen, angle_min, angle_max]   # scans with ≥ 10 of them,
      rows: [...]                    # and the signed angle range over those scans (doors never seen: no row)
                                     # (optional: without it, evaluation cannot tell which doors the laser saw move)
    people: [{name, radius, height, speed, start_ns, mode, path: [[x, y], ...]}]
    sensors: {laser: {frame_id, x, y, z, yaw}, camera: {frame_id, x, y, z, yaw, width, height, k}}
    scenario: {...}                  # the resolved scenario, as validated

Door fields use the column names of ``doors.parquet`` (DESIGN.md). ``door_angles`` holds the doors' angles
exactly: ``np.interp(t, stamps_of_door, angles_of_door)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_write_text


def output_paths(out: Path) -> dict[str, Path]:
    """The files the simulator writes for a log at ``out``: log, truth, trajectory, map_closed, map_static
    (here, not in the simulator, so that readers find them without importing it)."""
    out = Path(out)
    stem = out.name[: -len(out.suffix)] if out.suffix in (".mcap", ".bag") else out.name
    folder = out.parent
    return {"log": out, "truth": folder / f"{stem}.truth.yaml", "trajectory": folder / f"{stem}.truth.tum",
            "map_closed": folder / f"{stem}.map_closed.yaml", "map_static": folder / f"{stem}.map_static.yaml"}

FORMAT = "doorbatch-sim-truth/1"
FloatArray = npt.NDArray[np.float64]
Int64Array = npt.NDArray[np.int64]


@dataclass(frozen=True)
class TruthDoor:
    """One door of the truth world (fields as in doors.parquet; angles in rad)."""

    door_id: int
    name: str
    hinge_x: float
    hinge_y: float
    length: float
    closed_yaw: float
    opening_sign: int
    max_angle: float
    height: float
    color_mean_rgb: tuple[float, float, float]
    color_std_rgb: tuple[float, float, float]
    handle: dict[str, float] | None = None


@dataclass(frozen=True)
class TruthPass:
    """One pass: begins, doors stationary from ``stationary_ns``, ends."""

    index: int
    name: str
    begin_ns: int
    stationary_ns: int
    end_ns: int


@dataclass(frozen=True)
class SimTruth:
    """The content of a truth file."""

    generator: dict[str, Any]
    start_ns: int
    end_ns: int
    files: dict[str, str]
    world_name: str
    wall_height_m: float
    segments: FloatArray  # (N, 2, 2)
    segment_kinds: tuple[str, ...]
    doors: tuple[TruthDoor, ...]
    passes: tuple[TruthPass, ...]
    angle_stamp_ns: Int64Array  # (K,) knots
    angle_door_id: Int64Array  # (K,)
    angle_rad: FloatArray  # (K,) signed CCW relative to closed_yaw
    people: tuple[dict[str, Any], ...] = ()
    sensors: dict[str, Any] = field(default_factory=dict)
    scenario: dict[str, Any] = field(default_factory=dict)
    frame_id: str = "map"
    # (pass, door_id, laser_hits, scans_seen, angle_min, angle_max): what the laser saw of each leaf per pass;
    # None: the file does not say (a truth written by hand), unlike () (the laser saw no leaf)
    leaf_observations: tuple[tuple[float, ...], ...] | None = ()

    def door_angles_at(self, stamps_ns: npt.ArrayLike) -> FloatArray:
        """(K, D) signed door angles at the given stamps (linear between knots, constant outside)."""
        t = np.asarray(stamps_ns, dtype=np.int64).reshape(-1)
        cols = []
        for door in self.doors:
            sel = self.angle_door_id == door.door_id
            ref = int(self.angle_stamp_ns[sel][0]) if sel.any() else 0
            xp = (self.angle_stamp_ns[sel] - ref).astype(np.float64)
            cols.append(np.interp((t - ref).astype(np.float64), xp, self.angle_rad[sel]) if sel.any()
                        else np.zeros(t.shape[0]))
        return np.stack(cols, axis=1) if cols else np.zeros((t.shape[0], 0))

    def to_dict(self) -> dict[str, Any]:
        """The YAML document (plain Python types)."""
        rows = [[int(s), int(d), float(a)] for s, d, a in
                zip(self.angle_stamp_ns.tolist(), self.angle_door_id.tolist(), self.angle_rad.tolist(), strict=True)]
        return {
            "format": FORMAT,
            "generator": self.generator,
            "frame_id": self.frame_id,
            "start_ns": int(self.start_ns),
            "end_ns": int(self.end_ns),
            "files": dict(self.files),
            "world": {
                "name": self.world_name,
                "wall_height_m": float(self.wall_height_m),
                "segments": [[float(v) for v in s.ravel()] for s in self.segments],
                "segment_kinds": list(self.segment_kinds),
                "doors": [_door_dict(d) for d in self.doors],
            },
            "passes": [{"index": p.index, "name": p.name, "begin_ns": p.begin_ns, "stationary_ns": p.stationary_ns,
                        "end_ns": p.end_ns} for p in self.passes],
            "door_angles": {"columns": ["stamp_ns", "door_id", "angle"], "rows": rows},
            **({} if self.leaf_observations is None else {"leaf_observations": {
                "columns": ["pass", "door_id", "laser_hits", "scans_seen", "angle_min", "angle_max"],
                "rows": [list(r) for r in self.leaf_observations]}}),
            "people": [dict(p) for p in self.people],
            "sensors": self.sensors,
            "scenario": self.scenario,
        }


def _door_dict(d: TruthDoor) -> dict[str, Any]:
    return {
        "door_id": d.door_id, "name": d.name, "hinge_x": d.hinge_x, "hinge_y": d.hinge_y, "length": d.length,
        "closed_yaw": d.closed_yaw, "opening_sign": d.opening_sign, "max_angle": d.max_angle, "height": d.height,
        "color_mean_rgb": list(d.color_mean_rgb), "color_std_rgb": list(d.color_std_rgb), "handle": d.handle,
    }


def write_truth(truth: SimTruth, path: Path) -> None:
    """Write the truth YAML atomically (deterministic: same content, same bytes)."""
    text = "# doorbatch simulator ground truth (SI units, map frame, radians)\n"
    text += yaml.safe_dump(truth.to_dict(), sort_keys=False, default_flow_style=None, width=100)
    atomic_write_text(path, text)


def _leaf_observations(value: object) -> tuple[tuple[Any, ...], ...] | None:
    """The truth's ``leaf_observations`` rows: None where the key is missing (a hand-written truth), empty for an
    empty list or mapping.

    Raises:
        TypeError: neither a mapping with ``rows`` nor a list of rows.
    """
    if value is None:
        return None
    rows = value.get("rows") if isinstance(value, dict) else value
    if not isinstance(rows, (list, tuple)) and rows is not None:
        raise TypeError(f"leaf_observations: expected rows, got {type(rows).__name__}")
    return tuple(tuple(r) for r in rows or [])


_NO_COLOR = (math.nan, math.nan, math.nan)


def _truth_door(d: dict[str, Any], wall_height_m: float) -> TruthDoor:
    """A door entry; what scoring does not need (name, height, colours, handle) may be left out of a hand-written
    truth."""
    door_id = int(d["door_id"])
    return TruthDoor(door_id, str(d.get("name", f"door{door_id}")), float(d["hinge_x"]), float(d["hinge_y"]),
                     float(d["length"]), float(d["closed_yaw"]), int(d["opening_sign"]), float(d["max_angle"]),
                     float(d.get("height", wall_height_m)), tuple(d.get("color_mean_rgb", _NO_COLOR)),
                     tuple(d.get("color_std_rgb", _NO_COLOR)), d.get("handle"))


def read_truth(path: Path) -> SimTruth:
    """Read a truth file. Required: ``format``, ``world.doors`` (``door_id``, hinge, ``length``, ``closed_yaw``,
    ``opening_sign``, ``max_angle`` each) and ``door_angles``; the rest of the layout above may be left out of a
    truth written by hand (empty or NaN where scoring does not use it).

    Raises:
        InputDataError: unreadable, not YAML, another format, or a missing required key (named).
    """
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as err:
        raise InputDataError(f"cannot read truth file: {err}", path=path) from err
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise InputDataError(f"not a doorbatch truth file (expected format {FORMAT})", path=path)
    where = "world"
    try:
        world = doc["world"]
        wall_height_m = float(world.get("wall_height_m", math.nan))
        doors = []
        for k, d in enumerate(world["doors"]):
            where = f"world.doors[{k}]"
            doors.append(_truth_door(d, wall_height_m))
        where = "door_angles"
        rows = np.asarray(doc["door_angles"]["rows"], dtype=object).reshape(-1, 3)
        where = "passes"
        passes = tuple(TruthPass(int(p["index"]), str(p.get("name", f"pass{p['index']}")), int(p["begin_ns"]),
                                 int(p["stationary_ns"]), int(p["end_ns"])) for p in doc.get("passes") or ())
        where = "world.segments"
        segments = np.asarray(world.get("segments", []), dtype=np.float64).reshape(-1, 2, 2)
        where = "leaf_observations"
        leaves = _leaf_observations(doc.get("leaf_observations"))
        unknown = sorted({int(r[1]) for r in leaves or ()} - {d.door_id for d in doors})
        if unknown:
            raise InputDataError(f"truth file's leaf_observations name door_id {unknown}, which world.doors lacks",
                                 path=path)
        return SimTruth(
            generator=dict(doc.get("generator") or {}),
            start_ns=int(doc.get("start_ns", int(rows[:, 0].min()) if len(rows) else 0)),
            end_ns=int(doc.get("end_ns", int(rows[:, 0].max()) if len(rows) else 0)),
            files=dict(doc.get("files") or {}),
            world_name=str(world.get("name", "")),
            wall_height_m=wall_height_m,
            segments=segments,
            segment_kinds=tuple(world.get("segment_kinds", ("wall",) * len(segments))),
            doors=tuple(doors),
            passes=passes,
            angle_stamp_ns=np.array([int(v) for v in rows[:, 0]], dtype=np.int64),
            angle_door_id=np.array([int(v) for v in rows[:, 1]], dtype=np.int64),
            angle_rad=np.array([float(v) for v in rows[:, 2]], dtype=np.float64),
            people=tuple(doc.get("people") or ()),
            sensors=dict(doc.get("sensors") or {}),
            scenario=dict(doc.get("scenario") or {}),
            frame_id=str(doc.get("frame_id", "map")),
            leaf_observations=leaves,
        )
    except KeyError as err:
        raise InputDataError(f"truth file lacks {where}'s key {err} (required: world.doors with door_id, hinge_x, "
                             "hinge_y, length, closed_yaw, opening_sign, max_angle; door_angles.rows)",
                             path=path) from err
    except (TypeError, ValueError, IndexError, AttributeError) as err:
        raise InputDataError(f"truth file is malformed at {where} ({type(err).__name__}: {err})", path=path) from err


def merge_truths(truths: Sequence[SimTruth], paths: Sequence[Path]) -> SimTruth:
    """One truth for passes recorded apart, each beside its own truth file (a simulator restarted per pass: clocks
    that overlap, Gazebo and Stage starting at 0): the first file's world; every file's passes, door angles and
    leaf observations put on one time line, file after file (each shifted to start 1 s after the previous one
    ends), with each file's door angles held from its start to its end so that none leans toward the next file's.

    Raises:
        InputDataError: the files describe different doors (ids, or hinges more than 1 cm apart).
    """
    first = truths[0]
    hinges = {d.door_id: (d.hinge_x, d.hinge_y) for d in first.doors}
    rows: list[tuple[int, int, float]] = []
    passes: list[TruthPass] = []
    leaves: list[tuple[float, ...]] | None = []
    end_ns = first.start_ns - 1_000_000_000
    for truth, path in zip(truths, paths, strict=True):
        other = {d.door_id: (d.hinge_x, d.hinge_y) for d in truth.doors}
        if other.keys() != hinges.keys() or any(math.dist(other[k], hinges[k]) > 0.01 for k in hinges):
            raise InputDataError(f"the mapping truths beside a map's logs describe different doors than {paths[0]}",
                                 path=path)
        shift = end_ns + 1_000_000_000 - truth.start_ns
        ends = np.array([truth.start_ns, truth.end_ns], dtype=np.int64)
        held = truth.door_angles_at(ends)  # (2, D)
        for k, door in enumerate(truth.doors):
            own = truth.angle_door_id == door.door_id
            knots = zip([*ends, *truth.angle_stamp_ns[own]], [*held[:, k], *truth.angle_rad[own]], strict=True)
            rows += [(int(s) + shift, door.door_id, float(a)) for s, a in knots]
        base = len(passes)
        passes += [TruthPass(base + j, p.name, p.begin_ns + shift, p.stationary_ns + shift, p.end_ns + shift)
                   for j, p in enumerate(truth.passes)]
        if truth.leaf_observations is None or leaves is None:
            leaves = None
        else:
            leaves += [(base + int(r[0]), *r[1:]) for r in truth.leaf_observations]
        end_ns = truth.end_ns + shift
    rows.sort(key=lambda r: (r[1], r[0]))
    return replace(first, end_ns=end_ns, passes=tuple(passes),
                   angle_stamp_ns=np.array([r[0] for r in rows], dtype=np.int64),
                   angle_door_id=np.array([r[1] for r in rows], dtype=np.int64),
                   angle_rad=np.array([r[2] for r in rows], dtype=np.float64),
                   leaf_observations=None if leaves is None else tuple(leaves))
