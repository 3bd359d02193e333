"""``doorbatch localize``: MCL or the RBPF over one log, on a map directory (or any map_server map).

The stage in outline::

    recording  = scans, odometry (and a reference) of the log
    map        = static occupancy map → distance field; doors.parquet → doors (none for a plain map)
    particles  = initial set: around the reference / a given pose, or uniform over free space (global)
    for scan:    odometry at the scan → one filter update when the robot moved enough
    result     = weighted mean and covariance, door angles, particles per update
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, LocalizeConfig, config_of, parse_init, start_of
from doorbatch.errors import InputDataError, PipelineError, UsageError
from doorbatch.geometry.odometry import sideways_share
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.log_clock import LogClock, long_gaps
from doorbatch.io.map_server import as_written, read_map
from doorbatch.io.map_topic import read_map_topic
from doorbatch.io.mapdir import ODOMETRY_FRAME_SOURCES, door_set_of_previews, map_pose_source, read_doors_moved
from doorbatch.io.pose_topic import StartPose, read_start_poses
from doorbatch.io.recording import PoseSeries, Recording, load_recording
from doorbatch.io.roles import is_initial_pose_topic
from doorbatch.maps import DoorSet, OccupancyMap
from doorbatch.pipeline.door_rows import grid_rows
from doorbatch.pipeline.localize.clusters import heaviest_cluster_mean
from doorbatch.pipeline.localize.convergence import (
    ConvergenceMonitor,
    fits,
    multimodal,
    multimodal_note,
    scan_fit,
    see_through_share,
)
from doorbatch.pipeline.localize.door_geometry import (
    hinge_unknown,
    other_end,
    subset_doors,
    with_closed_in_range,
    with_unmoved_swing,
)
from doorbatch.pipeline.localize.door_observation import leaves_outside_range
from doorbatch.pipeline.localize.likelihood_field import (
    OCCUPIED_AT_LEAST,
    BeamCombination,
    DistanceField,
    FreeCells,
    build_distance_field,
    free_cells,
)
from doorbatch.pipeline.localize.mcl import (
    MclState,
    beams_from_scan,
    global_particles,
    initial_particles,
    mcl_step,
)
from doorbatch.pipeline.localize.particles import ParticleSet
from doorbatch.pipeline.localize.rbpf import rbpf_step, standing_still, within_of
from doorbatch.pipeline.localize.resampling import RecoveryState
from doorbatch.pipeline.localize.result import LocalizationResult, StillDoorStates
from doorbatch.pipeline.localize.rival_pose import Rival, RivalOutcome, RivalSearch, find_rival, scan_cloud
from doorbatch.pipeline.localize.torch_field import check_device
from doorbatch.pipeline.mapping import DoorMap, pass_poses
from doorbatch.progress import Progress

log = logging.getLogger(__name__)
FloatArray = npt.NDArray[np.float64]
# How a run starts: "reference", "global", a pose (x, y, yaw), or the first pose of a topic.
Init = str | tuple[float, float, float] | StartPose


@dataclass(frozen=True)
class LocalizationMap:
    """What localization needs of a map: the static map, its distance field, free cells, doors."""

    occupancy: OccupancyMap
    field: DistanceField
    free: FreeCells
    doors: DoorSet
    # A doorbatch map's pose source (its manifest's): "scanmatch" and "odometry" maps lie in their first pass's
    # odometry frame, not a reference's. None: not known (another tool's map).
    pose_source: str | None = None
    # (D,) doors that never moved while mapping and were seen closed: their hinge may be at their free end
    # (door_geometry.hinge_unknown). None: none such.
    hinge_unknown: npt.NDArray[np.bool_] | None = None

    @classmethod
    def of(cls, occ: OccupancyMap, doors: DoorSet, config: LocalizeConfig,
           pose_source: str | None = None) -> LocalizationMap:
        """The map ``occ`` with ``doors``, its likelihood field as the config asks and its free cells."""
        return cls(occ, localization_field(occ, config), free_cells(occ, config.map_free_at_most), doors, pose_source)


def is_map_log(map_path: Path) -> bool:
    """Whether ``--map`` names a log (its OccupancyGrid topic is the map) rather than a map directory or a
    map_server YAML file."""
    return not (map_path / "map.yaml").is_file() and map_path.suffix not in (".yaml", ".yml")


def map_doors_file(map_path: Path) -> Path | None:
    """The doors.parquet of ``--map``: in a map directory, or beside the map YAML named directly (a doorbatch
    map directory's map.yaml, or one renamed: office.yaml beside its doors.parquet)."""
    folder = map_path if map_path.is_dir() else map_path.parent if map_path.suffix in (".yaml", ".yml") else None
    doors = folder / "doors.parquet" if folder is not None else None
    return doors if doors is not None and doors.is_file() else None


def map_input_files(map_path: Path) -> list[Path]:
    """The files of ``--map`` a manifest lists: the map YAML (or the log holding the map) and its doors."""
    doors = map_doors_file(map_path)
    return [map_path / "map.yaml" if (map_path / "map.yaml").is_file() else map_path, *([doors] if doors else [])]


def load_localization_map(map_path: Path | str, config: LocalizeConfig | DoorbatchConfig | None = None
                          ) -> LocalizationMap:
    """A map directory (map.yaml + doors.parquet), a map_server YAML file from any SLAM tool, or a log with a
    nav_msgs/OccupancyGrid topic (``config.map_topic``; :mod:`doorbatch.io.map_topic`), such as the bag of a Nav2
    session. ``config``: the localize section, or the whole config (None: the defaults)."""
    map_path = Path(map_path)
    config = (config.localize if isinstance(config, DoorbatchConfig) else config) or LocalizeConfig()
    if map_path.is_dir() and not (map_path / "map.yaml").is_file() and not (map_path / "metadata.yaml").is_file():
        raise UsageError(f"--map {map_path}: the folder has no map.yaml (a doorbatch map directory) and is no "
                         f"ROS 2 bag")
    doors, unknown = DoorSet.empty(), None
    if is_map_log(map_path):
        occ = read_map_topic(map_path, config.map_topic)
    else:
        yaml_path = map_path / "map.yaml" if map_path.is_dir() else map_path
        occ = read_map(yaml_path)
        doors_path = map_doors_file(map_path)
        if doors_path is not None:
            doors, unknown = _localized_doors(*read_doors_moved(doors_path.parent), config)
    return _with_doors(occ, doors, unknown, config, map_pose_source(map_path))


def localization_map_of(door_map: DoorMap, config: LocalizeConfig) -> LocalizationMap:
    """The map :func:`~doorbatch.pipeline.mapping.build_map` returns as :func:`load_localization_map` reads it
    back from the map directory ``doorbatch map`` writes of it (its grid stage's doors; the static map
    trinary, as map.pgm holds it), without files: a notebook's ``localize(log, build_map(logs))``."""
    rows = grid_rows(door_map.doors, len(door_map.passes))
    mapped = door_set_of_previews([r.door for r in rows])
    doors, unknown = _localized_doors(mapped, np.array([r.door.moved for r in rows], dtype=np.bool_), config)
    return _with_doors(as_written(door_map.static_map), doors, unknown, config, door_map.pose_source)


def _localized_doors(mapped: DoorSet, moved: npt.NDArray[np.bool_], config: LocalizeConfig
                     ) -> tuple[DoorSet, npt.NDArray[np.bool_]]:
    """A map's doors as localization takes them: those that never moved may swing a little either way
    (:func:`with_unmoved_swing`), and which end of such a door is its hinge may be unknown (:func:`hinge_unknown`)."""
    unmoved = ~moved
    side_known = math.radians(config.door_angle_margin_deg)
    doors = with_unmoved_swing(mapped, unmoved, math.radians(config.door_unmoved_swing_deg), side_known)
    return doors, hinge_unknown(unmoved, mapped, side_known)


def _with_doors(occ: OccupancyMap, doors: DoorSet, unknown: npt.NDArray[np.bool_] | None, config: LocalizeConfig,
                pose_source: str | None) -> LocalizationMap:
    """:meth:`LocalizationMap.of` with the doors' closed direction in their range, and the doors whose hinge end
    is unknown (None or none: not kept)."""
    lmap = LocalizationMap.of(occ, with_closed_in_range(doors), config, pose_source)
    return replace(lmap, hinge_unknown=unknown) if unknown is not None and unknown.any() else lmap


def truth_localization_map(truth_path: Path, config: LocalizeConfig) -> LocalizationMap:
    """The map a simulated log deserves (for experiments): the simulator's static truth map (``map_static``, no
    leaves) and every door of the world with its full opening range, moved or not."""
    from doorbatch.io.sim_truth import read_truth

    truth = read_truth(truth_path)
    if "map_static" not in truth.files:
        raise InputDataError("truth file names no files.map_static (the simulator's door-less map)", path=truth_path)
    occ = read_map(truth_path.parent / truth.files["map_static"])
    ds = truth.doors
    reach = np.array([d.opening_sign * d.max_angle for d in ds])
    doors = DoorSet(np.array([[d.hinge_x, d.hinge_y] for d in ds]).reshape(-1, 2), np.array([d.length for d in ds]),
                    np.array([d.closed_yaw for d in ds]), np.minimum(reach, 0.0), np.maximum(reach, 0.0))
    return LocalizationMap.of(occ, doors, config)


def localization_field(occ: OccupancyMap, config: LocalizeConfig) -> DistanceField:
    """The likelihood field of a map as the config asks: its cap, unknown cells, and backend (NumPy or torch).

    Raises:
        OptionalDependencyError: ``backend: torch`` without torch installed.
        UsageError: ``backend: torch`` on a device torch cannot use.
    """
    device = None
    if config.backend == "torch":
        check_device(config.torch_device)
        device = config.torch_device
    return build_distance_field(occ, config.laser_likelihood_max_dist, config.unknown_as_max_dist,
                                config.map_occupied_at_least,
                                torch_device=device)


def laser_to_base_4x4(affine: FloatArray) -> FloatArray:
    """A scan's planar laser→base affine (2 × 3, ``ScanSet.laser_to_base``) as the 4 × 4 transform the beam
    model takes; z flipped where the 2 × 2 part is a reflection (an upside-down laser)."""
    mat = np.eye(4)
    mat[:2, :2] = affine[:, :2]
    mat[:2, 3] = affine[:, 2]
    mat[2, 2] = float(np.sign(np.linalg.det(affine[:, :2]))) or 1.0
    return mat


def lost_note(t_s: float, recent: Sequence[tuple[int, float, float]], config: LocalizeConfig,
              global_start: bool = False, off_map_at: FloatArray | None = None) -> str:
    """The warning for a run found lost at ``t_s``, naming the criterion that held over the ``recent`` updates
    (stamp, :func:`.scan_fit`, :func:`.see_through_share`). Hits off the walls while almost no beam passes through
    one (a mean share under a quarter of ``lost_max_see_through``, what a right pose shows) suggest a map lacking
    what the robot sees rather than a wrong pose (:mod:`.convergence`, criterion 4). From a ``global_start`` the
    likeliest cause is named too: a cloud that settled on the wrong one of similar places. ``off_map_at``: the
    estimate then, where it lies off the map's free cells (a cloud driven through a wall, or off the map)."""
    fit = np.array([r[1] for r in recent])
    through = np.array([r[2] for r in recent])
    wrong_place = ("; from a global start, also a cloud that settled on the wrong one of similar places (rooms that "
                   "repeat, a symmetric corridor) once the robot reaches what tells them apart: "
                   "localize.relocalize_when_lost spreads it again" if global_start else "")
    off = ("" if off_map_at is None else
           f"; the estimate, ({off_map_at[0]:.2f}, {off_map_at[1]:.2f}), lies off the map's free space")
    if not np.all(fit < config.lost_min_fit):
        return (f"lost at {t_s:.1f} s: over {config.lost_max_see_through:.0%} of the scans' beams passed through "
                f"the map's walls to end where it has none, for {config.lost_after_s} s (while most hits lay near "
                f"walls: a pose shifted along a corridor, or a kidnapped robot{wrong_place}){off}")
    note = (f"lost at {t_s:.1f} s: under {config.lost_min_fit:.0%} of the scans' hits within "
            f"{config.lost_fit_distance_m} m of the map for {config.lost_after_s} s")
    share = float(np.nanmean(through)) if np.isfinite(through).any() else math.nan
    if share < config.lost_max_see_through / 4:
        note += (f"; only {share:.0%} of their beams passed through its walls, so the beams end short of them: the "
                 "robot is elsewhere, or the map lacks what it sees (people, moved furniture, a missing wall)")
    return note + wrong_place + off


def _initial_particles(rec: Recording, lmap: LocalizationMap, init: Init, method: str, config: LocalizeConfig,
                       rng: np.random.Generator) -> ParticleSet:
    if init == "global":
        particles = global_particles(lmap.free, config.global_particles, rng)
    elif isinstance(init, StartPose):  # the message's spread, as AMCL's handleInitialPose; without one the
        # config's (AMCL would put every particle on the one pose, a cloud that cannot absorb any error)
        sigma = init.sigma if init.sigma is not None else (
            config.init_sigma_xy_m, config.init_sigma_xy_m, math.radians(config.init_sigma_yaw_deg))
        particles = ParticleSet.gaussian(init.pose, sigma, config.max_particles, rng)
    else:
        if init == "reference":
            if rec.reference is None:
                raise PipelineError(f"{rec.path}: --init reference but the log has no reference pose topic")
            mean = reference_start(rec.reference, int(rec.scans.stamps_ns[0]))
        else:
            mean = np.asarray(init, dtype=np.float64)
        particles = initial_particles(mean, config, rng)
    d = len(lmap.doors) if method == "rbpf" else 0
    doors = lmap.doors if d else subset_doors(lmap.doors, np.zeros(0, dtype=np.intp))
    particles.door_mean, particles.door_var = initial_door_states(doors, len(particles), init == "global", config, rng)
    return particles


def reference_start(reference: PoseSeries, stamp_ns: int) -> FloatArray:
    """The reference pose at ``stamp_ns`` (the first scan's): interpolated, or its first pose where it does not
    cover that stamp (``--init reference``)."""
    pose, ok = interpolate_poses(reference.stamps_ns, reference.poses, np.array([stamp_ns], dtype=np.int64))
    return np.asarray(pose[0] if ok[0] else reference.poses[0], dtype=np.float64)


def initial_door_states(doors: DoorSet, n: int, global_start: bool, config: LocalizeConfig,
                        rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Per particle and door the initial angle mean and variance (n, D).

    A tracked start: mid-range, std ``door_init_sigma_deg``. A global start with ``door_global_init`` "sampled":
    the door prior is uniform over each door's range, which one Gaussian per particle cannot hold ("closed or
    open"), so each particle's filter starts at an angle drawn uniformly from the range with std
    ``door_global_init_sigma_deg`` (the particles' mixture is the uniform prior; expert choice, the paper gives
    no global door prior).
    """
    d = len(doors)
    if global_start and d and config.door_global_init == "sampled":
        mean = rng.uniform(doors.angle_min, doors.angle_max, (n, d))
        return mean, np.full((n, d), math.radians(config.door_global_init_sigma_deg) ** 2)
    mid = (doors.angle_min + doors.angle_max) / 2
    return np.broadcast_to(mid, (n, d)).copy(), np.full((n, d), math.radians(config.door_init_sigma_deg) ** 2)


def _seen_often(seen: npt.NDArray[np.float64], min_updates: int) -> list[tuple[int, npt.NDArray[np.float64]]]:
    """The doors (columns of ``seen``: (updates, D) angles, NaN where not seen) seen in at least ``min_updates``
    updates, each with the angles it was seen at."""
    often = np.flatnonzero(np.sum(np.isfinite(seen), axis=0) >= min_updates).tolist()
    return [(d, seen[np.isfinite(seen[:, d]), d]) for d in often]


def outside_range_notes(seen: npt.NDArray[np.float64], doors: DoorSet, min_updates: int) -> list[str]:
    """Warnings for doors whose leaf was seen outside its opening range (``seen``: (updates, D) angles from
    :func:`leaves_outside_range`, NaN where not) in at least ``min_updates`` updates: the median angle seen, the
    mapped range and what it costs."""
    notes = []
    for d, angles in _seen_often(seen, min_updates):
        notes.append(f"door {doors.ids[d]} (hinge {doors.hinge[d, 0]:.2f}, {doors.hinge[d, 1]:.2f}): its leaf was "
                     f"seen at {math.degrees(float(np.median(angles))):.0f}° in {angles.size} updates, outside its "
                     f"mapped range {math.degrees(float(doors.angle_min[d])):.0f}° to "
                     f"{math.degrees(float(doors.angle_max[d])):.0f}° (no mapping pass showed it there): its angle "
                     "there is not estimated and its leaf counts as clutter; a map from passes that show the door "
                     "there knows it")
    return notes


def other_end_notes(seen: npt.NDArray[np.float64], flipped: DoorSet, min_updates: int) -> list[str]:
    """Warnings for never-moved doors whose leaf was seen swinging about their free end (``seen``: (updates, K)
    angles from :func:`leaves_outside_range` on :func:`~door_geometry.other_end` of them, NaN where not) in at
    least ``min_updates`` updates."""
    notes = []
    for k, angles in _seen_often(seen, min_updates):
        x, y = flipped.hinge[k]
        angle = math.degrees(float(np.median(angles)))
        notes.append(f"door {flipped.ids[k]}: its leaf was seen swinging about its other end ({x:.2f}, {y:.2f}), "
                     f"at {angle:.0f}° from closed in {angles.size} updates: the map has its hinge at the free end (a "
                     "door that never moved while mapping shows no hinge; mapping passes that show it open tell), so "
                     "its angle is not estimated and its leaf counts as clutter")
    return notes


@dataclass
class _Track:
    """Per-update estimates, appended during the run."""

    stamps: list[int] = field(default_factory=list)
    pose: list[FloatArray] = field(default_factory=list)
    cov: list[FloatArray] = field(default_factory=list)
    odom: list[FloatArray] = field(default_factory=list)
    n: list[int] = field(default_factory=list)
    neff: list[float] = field(default_factory=list)
    dmean: list[FloatArray] = field(default_factory=list)
    dstd: list[FloatArray] = field(default_factory=list)
    observed: list[npt.NDArray[np.bool_]] = field(default_factory=list)
    particles: list[FloatArray] = field(default_factory=list)
    still: list[tuple[int, FloatArray, FloatArray, npt.NDArray[np.bool_]]] = field(default_factory=list)

    def add(self, stamp: int, pose: FloatArray, cov: FloatArray, odom: FloatArray, n: int, neff: float,
            dmean: FloatArray, dstd: FloatArray, observed: npt.NDArray[np.bool_], particles: FloatArray) -> None:
        self.stamps.append(stamp)
        self.pose.append(pose)
        self.cov.append(cov)
        self.odom.append(odom)
        self.n.append(n)
        self.neff.append(neff)
        self.dmean.append(dmean)
        self.dstd.append(dstd)
        self.observed.append(observed)
        self.particles.append(particles)

    def add_doors(self, stamp: int, dmean: FloatArray, dstd: FloatArray, observed: npt.NDArray[np.bool_]) -> None:
        """Door estimates of an update that held the pose (``door_update_when_still``)."""
        self.still.append((stamp, dmean, dstd, observed))

    def result(self, log_name: str, method: str, n_doors: int, converged_ns: int | None, is_ambiguous: bool,
               warnings: list[str], log_clock: LogClock | None = None, lost_ns: list[int] | None = None,
               odom_frame_id: str = "", door_ids: npt.NDArray[np.int32] | None = None) -> LocalizationResult:
        u = len(self.stamps)
        return LocalizationResult(
            log=log_name, method=method, stamps_ns=np.asarray(self.stamps, dtype=np.int64),
            pose=np.asarray(self.pose), cov=np.asarray(self.cov), odom=np.asarray(self.odom),
            n_particles=np.asarray(self.n, dtype=np.int32), neff=np.asarray(self.neff, dtype=np.float64),
            door_mean=np.asarray(self.dmean).reshape(u, n_doors), door_std=np.asarray(self.dstd).reshape(u, n_doors),
            door_observed=np.asarray(self.observed, dtype=bool).reshape(u, n_doors),
            particles=np.asarray(self.particles), converged_ns=converged_ns, ambiguous=is_ambiguous,
            warnings=warnings, log_clock=log_clock, lost_ns=list(lost_ns or []), odom_frame_id=odom_frame_id,
            door_ids=door_ids, still_doors=StillDoorStates(
                np.asarray([s[0] for s in self.still], dtype=np.int64),
                np.asarray([s[1] for s in self.still], dtype=np.float64).reshape(len(self.still), n_doors),
                np.asarray([s[2] for s in self.still], dtype=np.float64).reshape(len(self.still), n_doors),
                np.asarray([s[3] for s in self.still], dtype=bool).reshape(len(self.still), n_doors)))


def start_scan_index(rec: Recording, start: StartPose) -> int:
    """The first scan at or after a start pose: by its header stamp; by its log time (on the scans' clock,
    :attr:`~doorbatch.io.recording.Recording.log_clock`) where the stamp is unset (0: ``rostopic pub`` leaves it
    so, and ROS 1 amcl reads it as "now", when the message comes) or lies after the last scan (another clock),
    with a warning.

    Raises:
        PipelineError: no scan comes after it on either clock.
    """
    last = int(rec.scans.stamps_ns[-1])
    at_log_time = rec.log_clock.stamp_at(start.log_time_ns)
    if start.stamp_ns == 0:
        rec.warnings.append(f"--init {start.topic}: its stamp is unset (0); started at its log time, when it came")
        candidates = [(at_log_time, "log time")]
    else:
        candidates = [(start.stamp_ns, "stamp"), (at_log_time, "log time")]
    for t, clock in candidates:
        if t <= last:
            if clock != "stamp" and start.stamp_ns != 0:
                rec.warnings.append(f"--init {start.topic}: its stamp is after the last scan (another clock?); "
                                    "started at its log time")
            return int(np.searchsorted(rec.scans.stamps_ns, t))
    raise PipelineError(f"{rec.path}: no scan after the start pose of {start.topic}")


def _reset_indices(rec: Recording, resets: Sequence[StartPose], first_i: int) -> dict[int, StartPose]:
    """The scan index at which each later initial pose takes effect (:func:`start_scan_index`; the last of several
    before one scan wins, the start's own scan included); those after the last scan are dropped."""
    at: dict[int, StartPose] = {}
    for r in resets:
        try:
            i = start_scan_index(rec, r)
        except PipelineError:
            rec.warnings.append(f"--init {r.topic}: a message after the last scan is not used")
            continue
        if i >= first_i:  # at the start's own scan: the later message replaces the start
            at[i] = r
    return at


def localize(log_path: Path | str, lmap: LocalizationMap | DoorMap | Path | str,
             config: DoorbatchConfig | Mapping[str, Any] | None = None, method: str = "rbpf",
             init: str | tuple[float, float, float] | Sequence[float] = "reference",
             progress: Progress | None = None) -> LocalizationResult:
    """Run MCL or the RBPF over a log (:func:`localize_recording` of the log's recording). ``init`` may also
    name a pose topic of the log (``/initialpose``): its first message is the start (:mod:`doorbatch.io.pose_topic`).
    ``lmap``: a :class:`LocalizationMap`, what :func:`~doorbatch.pipeline.mapping.build_map` returns
    (:func:`localization_map_of`), or what ``--map`` takes (:func:`load_localization_map`). ``config``: as
    :func:`~doorbatch.config.config_of` takes it (None: the defaults). ``init``: as ``--init`` takes it, or a pose
    (x, y, yaw) as any sequence of three numbers (:func:`~doorbatch.config.start_of`).

    Raises:
        PipelineError: --init reference without a reference, or a start pose after the last scan.
        UsageError: an unknown method or init, or an init topic the log lacks or that holds no pose.
        ConfigError: a config mapping with an unknown key or a wrong value.
    """
    config = config_of(config)
    log_path = Path(log_path)
    init = start_of(init)
    if isinstance(lmap, DoorMap):
        lmap = localization_map_of(lmap, config.localize)
    elif isinstance(lmap, str | Path):
        lmap = load_localization_map(Path(lmap), config.localize)
    if method not in ("mcl", "rbpf"):
        raise UsageError(f"--method {method!r}: expected rbpf or mcl")
    if isinstance(init, tuple) and not lmap.occupancy.contains(lmap.occupancy.world_to_cell(init[:2])):
        occ = lmap.occupancy
        corners = occ.cell_to_world([[0, 0], [occ.height - 1, occ.width - 1]])
        raise UsageError(f"--init {init[0]:g},{init[1]:g},{init[2]:g}: the position lies outside the map "
                         f"(cells from ({corners[0][0]:.2f}, {corners[0][1]:.2f}) to ({corners[1][0]:.2f}, "
                         f"{corners[1][1]:.2f}) m)")
    start: Init = init
    resets: list[StartPose] = []
    if isinstance(init, str) and init.startswith("/"):
        start, *later = read_start_poses(log_path, init)
        resets = later if is_initial_pose_topic(init) else []
    rec = load_recording(log_path, config)
    if isinstance(init, tuple) and (note := init_cell_note(lmap.occupancy, init)):
        rec.warnings.append(note)
    if method == "rbpf" and not len(lmap.doors):
        rec.warnings.append("--method rbpf on a map without doors (no doors.parquet, or none in it): no door is "
                            "estimated, and the filter weighs the static map only, as MCL does")
    if isinstance(start, StartPose) and start.frame_id not in ("", config.frames.map):
        rec.warnings.append(f"--init {start.topic}: its pose is in frame {start.frame_id!r}, taken as the map frame "
                            f"{config.frames.map!r}")
    if start != "global" and (note := start_fit_note(rec, lmap, start, config.localize)):
        rec.warnings.append(note)
    rec.warnings.extend(gap_notes(rec, config.io.gap_factor))
    if start == "reference" and rec.reference_is_odometry:
        rec.warnings.append("--init reference: the reference repeats the odometry (moved rigidly), so it may be no "
                            "map frame at all (a raw CARMEN log's): the start is its first pose, right where the map "
                            "lies in the reference's frame (doorbatch map puts it there from such logs); else give "
                            "--init X,Y,YAW or --init global")
    return localize_recording(rec, lmap, config, method, start, progress, resets)


def start_fit_note(rec: Recording, lmap: LocalizationMap, init: Init, lc: LocalizeConfig) -> str | None:
    """A warning when the first scan does not fit the map at the start pose (under ``lost_min_fit`` of its hits
    within ``lost_fit_distance_m``): the start is in another frame than the map (a reference in a simulator's
    world frame against a map from scan-matched poses, in the odometry's frame), or wrong."""
    if not len(rec.scans):
        return None
    if init == "reference":
        if rec.reference is None:
            return None
        start, i = reference_start(rec.reference, int(rec.scans.stamps_ns[0])), 0
    elif isinstance(init, StartPose):
        start, i = init.pose, min(start_scan_index(rec, init), len(rec.scans) - 1)
    else:
        start, i = np.asarray(init, dtype=np.float64), 0
    fit = scan_fit(lmap.field, start, rec.scans.hits_base(i), lc.lost_fit_distance_m)
    other_frame = init == "reference" and lmap.pose_source in ODOMETRY_FRAME_SOURCES
    if other_frame and not fit < lc.lost_min_fit:  # a shift along a corridor keeps the hits on its walls
        return (f"--init reference: the map was built from {lmap.pose_source} poses, so it lies in its first pass's "
                f"odometry frame, and the reference's start ({start[0]:.2f}, {start[1]:.2f}, {start[2]:.2f}) is in the "
                "reference's frame: where they differ (a simulator's world frame), the run is offset by the difference "
                "though the first scan fits the map; --init X,Y,YAW in the map's frame, or a map from the reference")
    if not fit < lc.lost_min_fit:  # NaN: too few hits to tell
        return None
    name = init.topic if isinstance(init, StartPose) else "reference" if init == "reference" else "X,Y,YAW"
    frame = (f"; the map was built from {lmap.pose_source} poses, so it lies in its first pass's odometry frame, "
             "not the reference's" if other_frame else "")
    return (f"--init {name}: at the start pose ({start[0]:.2f}, {start[1]:.2f}, {start[2]:.2f}) only {fit:.0%} of the "
            f"first scan's hits lie within {lc.lost_fit_distance_m} m of the map's walls{frame}: the start and the map "
            "may be in different frames; --init global or --init X,Y,YAW in the map's frame")


def gap_notes(rec: Recording, gap_factor: float) -> list[str]:
    """A warning where the scans stop for longer than ``gap_factor`` × their period (``io.gap_factor``, as ``inspect``
    tells): the run has no poses there. (Across an odometry gap the motion is interpolated: ``inspect`` tells it.)"""
    stamps = rec.scans.stamps_ns
    at = np.flatnonzero(long_gaps(np.diff(stamps), gap_factor))
    if not at.size:
        return []
    t0 = int(stamps[0])
    spans = ", ".join(f"{(int(stamps[i]) - t0) / 1e9:.1f}–{(int(stamps[i + 1]) - t0) / 1e9:.1f} s" for i in at[:5])
    return [f"{at.size} gap(s) in the scans ({spans}{' …' if at.size > 5 else ''} after the first scan): the "
            "trajectory has no poses there"]


def init_cell_note(occ: OccupancyMap, init: tuple[float, float, float]) -> str | None:
    """A warning when ``--init X,Y,YAW`` lies in a cell the map calls occupied or unknown (a robot stands in free
    space: a start there is likely a typo, or a yaw given in degrees where radians are meant), else None."""
    ij = occ.world_to_cell(init[:2])
    value = int(occ.occupancy[int(ij[0]), int(ij[1])]) if occ.contains(ij) else -1
    where = "unknown" if value < 0 else "occupied" if value >= OCCUPIED_AT_LEAST else None
    note = f"--init {init[0]:g},{init[1]:g},{init[2]:g}: the map's cell there is {where}" if where else None
    if abs(init[2]) > 2.0 * math.pi:
        note = (note + "; " if note else f"--init {init[0]:g},{init[1]:g},{init[2]:g}: ") + \
            f"yaw {init[2]:g} rad is more than a turn (yaw is in radians: {math.radians(init[2]):.4g} for degrees)"
    return note


def stopped_since(stamps_ns: npt.NDArray[np.int64], odom: FloatArray, ok: npt.NDArray[np.bool_], i: int,
                  lc: LocalizeConfig) -> bool:
    """Whether the robot has stood still at scan ``i`` for ``door_update_stopped_s``: the odometry of every scan in
    that window within ``door_update_stopped_m`` and ``_deg`` of scan ``i``'s (a docking approach at 1 cm/s is no
    stop, which would get a pose update per centimetre); a window the scans do not cover, at the log's start, is
    none."""
    since = int(stamps_ns[i]) - round(lc.door_update_stopped_s * 1e9)
    j = int(np.searchsorted(stamps_ns, since, side="left"))
    if j >= i or (j == 0 and int(stamps_ns[0]) > since) or not ok[j:i + 1].all():
        return False
    return bool(within_of(odom[j:i], odom[i], lc.door_update_stopped_m, lc.door_update_stopped_deg).all())


def with_laser_odometry(rec: Recording, config: DoorbatchConfig) -> Recording:
    """A recording without odometry given its scans matched at constant velocity as the motion input (laser
    odometry, as robots without wheel encoders feed AMCL from a scan matcher), with a warning.

    Raises:
        PipelineError: no scan got a pose.
    """
    matched = pass_poses(rec, "scanmatch", config)
    if not matched.valid.any():
        raise PipelineError(f"{rec.path}: no odometry, and scan matching gave no scan a pose")
    note = ("no odometry (nav_msgs/Odometry or TF odom→base_link): the motion input is the scans matched at "
            "constant velocity (laser odometry); a featureless corridor leaves it guessing along the corridor")
    odometry = PoseSeries(matched.stamps_ns[matched.valid], matched.poses[matched.valid], config.frames.odom)
    return replace(rec, odometry=odometry, warnings=[*rec.warnings, note])


def motion_model_for(odometry: PoseSeries, lc: LocalizeConfig) -> tuple[LocalizeConfig, str | None]:
    """The ``localize`` section with the motion model the odometry needs, and a warning when it moves sideways.

    Odometry that moves across its heading for more than ``omni_sideways_share`` of its travel
    (:func:`~doorbatch.geometry.odometry.sideways_share`) comes from a holonomic base: the differential model would
    take each strafe as a turn of ±90°, there and back, with the rotation noise of both. Then, unless the config
    names ``robot_model_type``, the omnidirectional model is used; if it names ``differential``, it is kept.
    """
    if lc.robot_model_type != "differential":
        return lc, None
    pose = odometry.poses
    share = sideways_share(pose[:, 0], pose[:, 1], pose[:, 2], lc.sideways_step_m)
    if not share > lc.omni_sideways_share:
        return lc, None
    moved = f"the odometry moves sideways for {100 * share:.0f} % of its travel (a holonomic base)"
    if "robot_model_type" in lc.model_fields_set:
        return lc, (f"{moved}, but the config sets robot_model_type differential, which takes each strafe as a turn "
                    "of ±90° there and back; set localize.robot_model_type=omnidirectional (and alpha5)")
    return (lc.model_copy(update={"robot_model_type": "omnidirectional"}),
            f"{moved}: localized with robot_model_type omnidirectional (Nav2's OmniMotionModel, strafe noise alpha5 "
            f"{lc.alpha5:g}); set localize.robot_model_type=differential to keep the differential model")


def localize_recording(rec: Recording, lmap: LocalizationMap, config: DoorbatchConfig, method: str = "rbpf",
                       init: Init = "reference", progress: Progress | None = None,
                       resets: Sequence[StartPose] = ()) -> LocalizationResult:
    """Run MCL or the RBPF over a recording (e.g. one whose odometry a script has replaced). A
    :class:`StartPose` start localizes only the scans from its stamp on (AMCL does nothing before its initial
    pose); each of ``resets`` (an /initialpose topic's later messages) starts the filter anew from the first scan
    at or after it, as AMCL's handleInitialPose does, with a warning.

    A recording without odometry moves by its scans matched at constant velocity (:func:`with_laser_odometry`).

    Raises:
        PipelineError: --init reference without a reference.
        UsageError: an unknown method.
    """
    if method not in ("mcl", "rbpf"):
        raise UsageError(f"--method {method!r}: expected rbpf or mcl")
    lc = config.localize
    rng = np.random.default_rng(config.seed if lc.seed is None else lc.seed)
    log_path = Path(rec.path)
    log.info("%s: %s over %d scans, %d map doors%s, start %s", rec.path, method, len(rec.scans), len(lmap.doors),
             "" if method == "rbpf" else " (mcl does not estimate them)", init)
    if rec.odometry is None:
        rec = with_laser_odometry(rec, config)
    assert rec.odometry is not None
    lc, motion_note = motion_model_for(rec.odometry, lc)
    odom, odom_ok = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, rec.scans.stamps_ns,
                                      int(config.mapping.max_pose_gap_s * 1e9))
    state = MclState(_initial_particles(rec, lmap, init, method, lc, rng), global_start=init == "global")
    free = lmap.free if (lc.recovery_alpha_fast > 0.0 or init == "global") else None
    combination = BeamCombination(lc.beam_combination)
    track = _Track()
    first_i = start_scan_index(rec, init) if isinstance(init, StartPose) else 0
    reset_at = _reset_indices(rec, resets, first_i)
    converged_ns = None if init == "global" else int(rec.scans.stamps_ns[first_i])
    monitor = ConvergenceMonitor()  # convergence claims of a global run; lost detection of every run
    warnings = [*rec.warnings, *([motion_note] if motion_note else [])]  # the run's own, not the recording's
    if lc.relocalize_when_lost and init != "global":
        warnings.append("localize.relocalize_when_lost spreads a lost cloud again only with --init global: this "
                        "run, once lost, goes on as it is (its lost times are still reported)")
    lost = barred = False
    lost_ns: list[int] = []
    fitting_since: int | None = None  # stamp of the first update of the current run of fitting scans
    recent: list[tuple[int, float, float]] = []  # the last lost_after_s of updates: stamp, fit, see-through
    last_s: float | None = None
    k_draw = max(1, lc.annotate_particles)
    updated_scans: list[int] = []  # the scan of each update
    outside: list[FloatArray] = []  # per RBPF update, each door's leaf angle where seen outside its range (NaN: not)
    unknown_rows = (np.flatnonzero(lmap.hinge_unknown) if method == "rbpf" and lmap.hinge_unknown is not None
                    else np.zeros(0, dtype=np.intp))
    flipped = other_end(subset_doors(lmap.doors, unknown_rows)) if unknown_rows.size else None
    tip_seen: list[FloatArray] = []  # per RBPF update, those doors' leaf angle about their free end (NaN: not)
    if progress is not None:
        progress.describe("localize")
        progress.set_total(len(rec.scans))
    for i in range(len(rec.scans)):
        if progress is not None:
            progress.update(1)
        if i in reset_at:  # an operator's pose again: a fresh cloud there, updated on this scan (pf_init_ false)
            state = MclState(_initial_particles(rec, lmap, reset_at[i], method, lc, rng))
            monitor, lost, barred, fitting_since = ConvergenceMonitor(), False, False, None
            warnings.append(f"--init {reset_at[i].topic}: started anew at "
                            f"{(rec.scans.stamps_ns[i] - rec.scans.stamps_ns[first_i]) / 1e9:.1f} s from its "
                            "message then (AMCL re-initializes on every initial pose)")
        if i < first_i or not odom_ok[i]:
            continue
        scan = rec.scans.scan(i)
        beams = beams_from_scan(scan, laser_to_base_4x4(rec.scans.laser_to_base[i]), lc)
        stamp_s = scan.stamp_ns / 1e9
        first = state.odom_at_update is None
        if method == "rbpf":
            held = state.odom_at_update
            stopped_past_update = (lc.door_update_when_still and held is not None and len(lmap.doors) > 0
                                   and not standing_still(held, odom[i], lc)  # the cheap test first: every scan
                                   and stopped_since(rec.scans.stamps_ns, odom, odom_ok, i, lc))
            state, diag, share = rbpf_step(state, odom[i], stamp_s, last_s, beams, rec.scans.hits_base(i),
                                           lmap.field, lmap.doors, lc, rng, free, force=first or stopped_past_update)
            # door_states' flag (less 1e-9: a share of every particle sums to 1 only within round-off); share > 0
            # is what any particle with weight saw
            observed = share >= lc.door_observed_min_share - 1e-9
        else:
            state, diag = mcl_step(state, odom[i], beams, lmap.field, lc, rng, free, force=first,
                                   combination=combination)
            observed = share = np.zeros(0, dtype=bool)
        if not diag.updated:
            if diag.doors_updated:  # the robot stands still: the doors were updated, the pose held
                last_s = stamp_s
                track.add_doors(scan.stamp_ns, *state.particles.door_estimate(), observed)
            continue
        last_s = stamp_s
        p = state.particles
        cloud_mean, cov = p.mean_and_covariance()
        mean = cloud_mean
        if lc.pose_estimate == "heaviest_cluster":
            mean = heaviest_cluster_mean(p, lc.kld_bin_xy_m, math.radians(lc.kld_bin_yaw_deg))
        dmean, dstd = p.door_estimate()
        hits = rec.scans.hits_base(i)
        fit = scan_fit(lmap.field, mean, hits, lc.lost_fit_distance_m)
        through = see_through_share(lmap.occupancy, lmap.field, mean, rec.scans.laser_to_base[i][:, 2], hits,
                                    lc.lost_fit_distance_m, lc.map_occupied_at_least, lc.lost_see_through_beams)
        recent = [*(r for r in recent if (scan.stamp_ns - r[0]) / 1e9 <= lc.lost_after_s),
                  (int(scan.stamp_ns), fit, through)]
        monitor = monitor.update(int(scan.stamp_ns), odom[i], p, lc, fit, through, cloud_mean)
        respread = monitor.lost and init == "global" and lc.relocalize_when_lost
        # the same cloud, once lost, claims nothing again; one that spread or split since (recovery's random
        # particles drew it elsewhere) is a new global localization, whose streak may claim again
        barred = (barred or (monitor.lost and not respread)) and not (monitor.since_ns is None and not monitor.lost)
        if init == "global":
            converged_ns = None if barred else monitor.converged_ns
        if monitor.lost and (respread or not lost):  # once per episode of poor fits, unless spread anew
            lost_ns.append(int(scan.stamp_ns))
            t_s = (scan.stamp_ns - (track.stamps[0] if track.stamps else scan.stamp_ns)) / 1e9  # as manifest_extra
            if len(lost_ns) == 1:  # the later episodes in one line at the end
                again = "; the cloud was spread over the free space again" if respread else ""
                off_map = None if lmap.free.holds(mean[None, :2])[0] else mean[:2]
                warnings.append(lost_note(t_s, recent, lc, init == "global", off_map) + again)
        if not math.isnan(fit):  # NaN (no evidence) neither starts nor breaks a run of fitting scans
            fitting_since = (fitting_since or int(scan.stamp_ns)) if fits(fit, through, lc) else None
        # an episode ends once the scans fit again for lost_after_s, as it began (a noisy share dips below the bar)
        lost = (lost or monitor.lost) and not (
            fitting_since is not None and (scan.stamp_ns - fitting_since) / 1e9 >= lc.lost_after_s)
        if respread:
            state = dataclasses.replace(state, particles=_initial_particles(rec, lmap, "global", method, lc, rng),
                                        recovery=RecoveryState())  # a fresh start, as AMCL's pf_init
        if method == "rbpf" and len(lmap.doors):
            outside.append(leaves_outside_range(hits, mean, lmap.doors, lc, math.radians(lc.door_behind_hinge_deg)))
            if flipped is not None:  # a leaf about the free end, where the door update found none about the hinge
                at_tip = leaves_outside_range(hits, mean, flipped, lc, math.radians(lc.door_behind_hinge_deg))
                tip_seen.append(np.where(share[unknown_rows] > 0, np.nan, at_tip))
        # a fixed-size draw of the (equally weighted after resampling) particles for the annotated MCAP
        pick = np.linspace(0, len(p) - 1, k_draw).round().astype(np.intp)
        track.add(scan.stamp_ns, mean, cov, odom[i], len(p), diag.neff, dmean, dstd, observed, p.pose[pick])
        updated_scans.append(i)
    if not track.stamps:
        raise PipelineError(f"{log_path}: no scan had an odometry pose; nothing was localized")
    if len(lost_ns) > 1:
        again = ", ".join(f"{(t - track.stamps[0]) / 1e9:.1f}" for t in lost_ns[1:])
        warnings.append(f"lost again at {again} s (each after the scans had fit for {lc.lost_after_s} s; the "
                        "manifest's lost_after_s lists every episode)")
    if len(track.stamps) == 1 and len(rec.scans) - first_i > 1:
        warnings.append(f"1 filter update over {len(rec.scans) - first_i} scans: the odometry "
                        f"({rec.odometry.frame_id}) never moved the robot by update_min_d {lc.update_min_d} m or "
                        f"update_min_a "
                        f"{lc.update_min_a} rad (a robot that stood still, or an odometry frame that does not move: "
                        "see frames.odom)")
    if outside:
        warnings += outside_range_notes(np.array(outside), lmap.doors, lc.door_outside_range_min_updates)
    if tip_seen and flipped is not None:
        warnings += other_end_notes(np.array(tip_seen), flipped, lc.door_outside_range_min_updates)
    ambiguous = multimodal(state.particles, lc)
    warnings.extend([multimodal_note(state.particles, lc, tracked=init != "global")] if ambiguous else [])
    if init == "global" and converged_ns is not None and lc.rival_check:
        streak_ns = monitor.claim_since_ns if monitor.claim_since_ns is not None else converged_ns
        tested = rival_tested_claim(rec, lmap, track, updated_scans, streak_ns, converged_ns, lc)
        converged_ns, ambiguous = tested.converged_ns, ambiguous or tested.ambiguous
        warnings.extend([tested.note] if tested.note else [])
    if init != "global" and converged_ns is not None and track.stamps:  # a tracked start: its first update, which
        converged_ns = max(converged_ns, track.stamps[0])  # odometry that begins after the first scan puts later
    n_doors = state.particles.n_doors
    result = track.result(Path(log_path).name, method, n_doors, converged_ns, ambiguous, warnings,
                          rec.log_clock, lost_ns, rec.odometry.frame_id, lmap.doors.ids[:n_doors])
    drawn = rec.drawn_odometry
    if drawn is None or drawn is rec.odometry or not len(result):
        return result
    at, ok = interpolate_poses(drawn.stamps_ns, drawn.poses, result.stamps_ns, int(config.mapping.max_pose_gap_s * 1e9))
    return replace(result, drawn_odom=np.where(ok[:, None], at, result.odom))  # where the tree has none: the used one


@dataclass(frozen=True)
class ClaimTest:
    """A global run's claim after the rival test: the claim that stands (None: none), whether the run is ambiguous,
    and the warning that says why (None: the claim stands as made)."""

    converged_ns: int | None
    ambiguous: bool
    note: str | None = None


def rival_tested_claim(rec: Recording, lmap: LocalizationMap, track: _Track, updated_scans: Sequence[int],
                       streak_ns: int, converged_ns: int, lc: LocalizeConfig) -> ClaimTest:
    """A global run's claim tested against the map (:mod:`.rival_pose`).

    The scans from the claimed streak's first update (``streak_ns``, when the cloud became tight) to the end, placed by
    the estimates, are searched for over the map's free poses: where they fit as well elsewhere (or better) the claim
    is withdrawn and the run is ambiguous. Else the claim moves to the first update from which the scans since the
    streak began leave no rival (a cloud tight on a pose the scans could not yet tell from another was right by
    chance until then): an exponential, then binary, search over the updates from the claim on, the scans only
    adding evidence.
    """
    settings = RivalSearch(lc.rival_resolution_m, lc.rival_sigma_m, lc.rival_search_ratio, lc.rival_search_points,
                           lc.rival_min_evidence_m, lc.rival_max_candidates, lc.ambiguity_radius_m,
                           math.radians(lc.ambiguity_yaw_deg))
    stamps = np.asarray(track.stamps, dtype=np.int64)
    first, claim_i = int(np.searchsorted(stamps, streak_ns)), int(np.searchsorted(stamps, converged_ns))
    end = len(stamps) - 1
    poses = np.asarray(track.pose[first:])
    hits = [rec.scans.hits_base(updated_scans[j]) for j in range(first, end + 1)]  # read once for every test

    def test(last: int) -> RivalOutcome:
        n = last - first + 1
        cloud = scan_cloud(poses[:n], hits[:n], poses[n - 1], lc.rival_resolution_m, lc.rival_cloud_points)
        return find_rival(lmap.field, lmap.free.free_mask, poses[n - 1], cloud, settings)

    def told(o: RivalOutcome) -> bool:
        return o.rival is None and not o.undecided

    t0, whole = int(stamps[0]), test(end)
    claim_s, streak_s = (converged_ns - t0) / 1e9, (streak_ns - t0) / 1e9
    if whole.undecided:
        return ClaimTest(converged_ns, False, (
            f"rival test left undecided: over {lc.rival_max_candidates} poses of the map still fit the scans since the "
            f"claim at {claim_s:.1f} s nearly as well (a very self-similar map); the claim stands untested "
            "(localize.rival_max_candidates)"))
    if whole.rival is not None:
        return ClaimTest(None, True, _rival_note(whole.rival, track.pose[end], streak_s, lc))
    lo, hi, k, last_rival = claim_i - 1, claim_i, 0, None
    while hi < end:
        o = test(hi)
        if told(o):
            break
        lo, last_rival, k = hi, o.rival, k + 1
        hi = min(claim_i + (1 << k) - 1, end)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        o = test(mid)
        if told(o):
            hi = mid
        else:
            lo, last_rival = mid, o.rival
    if hi == claim_i:
        return ClaimTest(converged_ns, False)
    where = "" if last_rival is None else (
        f" as well at ({last_rival.pose[0]:.2f}, {last_rival.pose[1]:.2f}, {math.degrees(last_rival.pose[2]):.0f}°)")
    return ClaimTest(int(stamps[hi]), False, (
        f"convergence claimed at {(stamps[hi] - t0) / 1e9:.1f} s, not {claim_s:.1f} s: until then the scans since the "
        f"cloud became tight ({streak_s:.1f} s) fit the map{where} (localize.rival_*); the cloud's pose "
        "was a pick the scans could not yet tell"))


def _rival_note(r: Rival, end: FloatArray, streak_s: float, lc: LocalizeConfig) -> str:
    """The warning for a claim withdrawn for a rival pose (:func:`rival_tested_claim`)."""
    span = f"the scans from when the cloud became tight ({streak_s:.1f} s) to the end"
    where = (f"({r.pose[0]:.2f}, {r.pose[1]:.2f}, {math.degrees(r.pose[2]):.0f}°)", f"({end[0]:.2f}, {end[1]:.2f}, "
             f"{math.degrees(end[2]):.0f}°)")
    if r.counter_m >= lc.rival_min_evidence_m:
        return (f"ambiguous: {span} fit the map better at {where[0]} than at the estimate's end pose {where[1]} "
                f"({r.counter_m:.1f} m of the wall seen fits only there, {r.evidence_m:.1f} m only at the estimate): "
                "the cloud settled on the wrong one of two similar places; no convergence is claimed")
    return (f"ambiguous: {span} fit the map as well at {where[0]} as at the estimate's end pose {where[1]} (score "
            f"{r.ratio:.0%} of its own; {r.evidence_m:.1f} m of the wall seen fits only the estimate, under "
            "localize.rival_min_evidence_m): the map is symmetric or repeats there, and the cloud kept one of the two "
            "by chance; no convergence is claimed")


@dataclass(frozen=True)
class LocalizeRunSummary:
    """What ``doorbatch localize`` wrote."""

    run_dir: str
    method: str
    updates: int
    mean_particles: float
    converged: bool
    converged_after_s: float | None
    ambiguous: bool
    lost_after_s: list[float]  # when each episode of scans that do not fit the estimate began (empty: never lost)
    warnings: int
    files: list[str]


def run_localize(log_path: Path, map_path: Path, out: Path, config: DoorbatchConfig, method: str,
                 init: str, progress: Progress | None = None
                 ) -> tuple[LocalizationResult, LocalizeRunSummary]:
    """Localize a log on a map and write the run directory: trajectory.parquet, door_states.parquet,
    trajectory.tum, annotated.mcap, manifest.json."""
    from doorbatch.io.annotated_mcap import on_log_clock, write_annotated_mcap
    from doorbatch.io.manifest import Manifest, StageTimer
    from doorbatch.io.rundir import run_annotations, write_run_tables
    from doorbatch.io.staged_dir import staged_files

    inputs = [log_path, *map_input_files(map_path)]
    manifest = Manifest.start(config.as_dict(), inputs, command="localize", method=method, init=init)
    timer = StageTimer()
    with timer("map"):
        lmap = load_localization_map(map_path, config.localize)
    with timer("localize"):
        result = localize(log_path, lmap, config, method, parse_init(init), progress)
    if progress is not None:
        progress.describe("localize: writing annotated.mcap")
    with staged_files(out) as stage:  # an interrupted write leaves ``out`` as it was
        with timer("write"):
            files = write_run_tables(stage, result)
            odom_frame = result.odom_frame_id or config.frames.odom
            if odom_frame != config.frames.odom:
                result.warnings.append(f"frames.odom is {config.frames.odom!r} but the log's odometry is in "
                                       f"{odom_frame!r}: annotated.mcap's map→odom transform names {odom_frame!r}, "
                                       "the frame the robot hangs from in the log's own TF tree")
            copy = write_annotated_mcap(log_path, stage / "annotated.mcap",
                                        on_log_clock(run_annotations(result, lmap.occupancy, lmap.doors,
                                                                     config.frames.map, odom_frame), result.log_clock),
                                        config, replaced_tf=[(config.frames.map, odom_frame)])
            if copy.replaced_transforms:
                result.warnings.append(f"the log's own {config.frames.map}→{odom_frame} ({copy.replaced_transforms} "
                                       "transforms on /tf: another localizer's) is left out of annotated.mcap, where "
                                       "doorbatch's own takes its place")
        for w in result.warnings:
            manifest.warn(w)
        manifest.extra.update(result.manifest_extra())
        converged_s = manifest.extra["converged_after_s"]
        manifest.finish(timer)
        manifest.write(stage / "manifest.json")
    files = [out / f.name for f in files]
    summary = LocalizeRunSummary(str(out), method, len(result), float(result.n_particles.mean()),
                                 result.converged_ns is not None, converged_s, result.ambiguous,
                                 list(manifest.extra["lost_after_s"]), len(result.warnings),
                                 [str(f) for f in [*files, out / "annotated.mcap", out / "manifest.json"]])
    return result, summary
