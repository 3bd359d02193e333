"""A log loaded into compact arrays for the stages: scans, odometry, reference poses, beam colors.

Scans keep their ranges as float32 plus, per scan, the planar affine map laser→base_link (a 2×3 matrix
from the TF tree at the scan's stamp: rotation or reflection for an upside-down laser, and translation).
Images are never loaded here; stages that need them stream the log themselves.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig, FramesConfig, IoConfig
from doorbatch.errors import LaserMountError, LogContentError, TransformError
from doorbatch.geometry.deskew import deskewed_scans
from doorbatch.geometry.odometry import (
    bridged_jumps,
    integrated_twist,
    odometry_jumps,
    odometry_teleports,
    sweep_smear_m,
)
from doorbatch.geometry.rotations import yaw_of_matrix
from doorbatch.geometry.se2 import compose, interpolate_poses, inverse, relative
from doorbatch.geometry.tf_buffer import TfBuffer
from doorbatch.geometry.veiling import veiling_mask
from doorbatch.io.decode import MODEL_STATES
from doorbatch.io.log_clock import LogClock
from doorbatch.io.reader import LogReader, open_log
from doorbatch.pipeline.evaluate.trajectory_error import first_pose_correction, rigid_copy_offset
from doorbatch.records import BeamColors, Pose2D, Role, Scan, Transform

FloatArray = npt.NDArray[np.float64]
R = TypeVar("R", Scan, Pose2D)
Int64Array = npt.NDArray[np.int64]
# A sweep (time_increment × beams) this much longer than the scan period is no sweep: rotating lidars sweep within a
# period. Expert choice: 10 % above it, for jitter in the stamps.
SWEEP_OVER_PERIOD = 1.1


@dataclass(frozen=True)
class PoseSeries:
    """Stamped planar poses: ``stamps_ns`` (N,) int64 sorted, ``poses`` (N, 3) x, y, yaw."""

    stamps_ns: Int64Array
    poses: FloatArray
    frame_id: str

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def around(self, start_ns: int, stop_ns: int) -> PoseSeries:
        """The poses stamped in [start_ns, stop_ns], with the one before and the one after, so that any time in
        that span interpolates as it did in the whole series."""
        i0 = max(int(np.searchsorted(self.stamps_ns, start_ns, side="left")) - 1, 0)
        i1 = int(np.searchsorted(self.stamps_ns, stop_ns, side="right")) + 1
        return replace(self, stamps_ns=self.stamps_ns[i0:i1], poses=self.poses[i0:i1])


@dataclass(frozen=True)
class ScanSet:
    """All scans of a log (S scans). ``ranges[i]`` is float32 (B_i,); beam j of scan i points at
    ``angle_min[i] + j · angle_increment[i]`` in the laser frame; ``laser_to_base[i]`` is 2×3."""

    stamps_ns: Int64Array
    ranges: list[npt.NDArray[np.float32]]
    angle_min: FloatArray
    angle_increment: FloatArray
    range_min: FloatArray
    range_max: FloatArray
    laser_to_base: FloatArray  # (S, 2, 3)
    frame_id: str

    def __len__(self) -> int:
        return int(self.stamps_ns.shape[0])

    def take(self, start: int, stop: int) -> ScanSet:
        """Scans start … stop − 1."""
        return replace(self, stamps_ns=self.stamps_ns[start:stop], ranges=self.ranges[start:stop],
                       angle_min=self.angle_min[start:stop], angle_increment=self.angle_increment[start:stop],
                       range_min=self.range_min[start:stop], range_max=self.range_max[start:stop],
                       laser_to_base=self.laser_to_base[start:stop])

    def scan(self, i: int) -> Scan:
        """Scan i as a :class:`Scan` record."""
        return Scan(int(self.stamps_ns[i]), int(self.stamps_ns[i]), self.frame_id, float(self.angle_min[i]),
                    float(self.angle_increment[i]), float(self.range_min[i]), float(self.range_max[i]),
                    self.ranges[i])

    def endpoints_base(self, i: int) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
        """(B_i, 2) beam end points of scan i in base_link (NaN where the range is not finite), and
        the hit mask (finite, range_min ≤ r < range_max)."""
        r = self.ranges[i].astype(np.float64)
        angles = self.angle_min[i] + self.angle_increment[i] * np.arange(r.shape[0])
        affine = self.laser_to_base[i]
        with np.errstate(invalid="ignore"):  # inf · sin(0) = NaN: a no-return beam straight ahead
            local = np.stack([r * np.cos(angles), r * np.sin(angles)], axis=1)
            hit = np.isfinite(r) & (r >= self.range_min[i]) & (r < self.range_max[i])
            points = local @ affine[:, :2].T + affine[:, 2]
        return points, hit

    def hits_base(self, i: int) -> FloatArray:
        """The hits of scan i (:meth:`endpoints_base`) in base_link, in beam order (K, 2)."""
        points, hit = self.endpoints_base(i)
        return points[hit]


@dataclass(frozen=True)
class Recording:
    """One log as arrays. ``colors[i]`` is (B_i, 3) uint8 aligned with scan i, when the log has colors;
    ``color_valid[i]`` (B_i,) marks the beams that have one (None: all that have a colour array)."""

    path: str
    scans: ScanSet
    odometry: PoseSeries | None
    reference: PoseSeries | None
    colors: list[npt.NDArray[np.uint8]] | None = None
    warnings: list[str] = field(default_factory=list)
    color_valid: list[npt.NDArray[np.bool_]] | None = None
    # Where the reference is the odometry moved rigidly (io.reference_repeats_odometry_m/_deg: no independent
    # reference), that motion (x, y, yaw), which takes odometry poses into the reference's frame; else None.
    odometry_to_reference: FloatArray | None = None
    # The recorder's clock against the scans' stamps where they differ by more than io.clock_mismatch_s (a sim-time
    # log recorded on wall-clock time), else the identity: when an output message stamped at a scan's time is
    # logged, so that it sits beside the input's messages (annotated.mcap).
    log_clock: LogClock = field(default_factory=LogClock)
    # The log's static transforms (its sensor mounts), for another pass of the same robot that lacks them
    # (:func:`load_passes`).
    mounts: tuple[Transform, ...] = ()
    # A piece of a log cut by time (:meth:`take`): the log's path and the piece's number (0: the first, or a whole
    # log). A later piece continues the one before it: one recording, one odometry frame.
    source_path: str = ""
    piece: int = 0
    # Where the log's odometry restarts were bridged (bridged_odometry), the rigid motion B that bridging
    # applied to its last pose (bridged = B ⊕ raw): a next pass whose odometry continues the driver's raw frame
    # takes B too (mapping.carried_bridges). None: nothing bridged.
    odometry_bridge: FloatArray | None = None
    # base_link's pose in the odometry's frame as the log's TF tree holds it (TF where the tree has that frame above
    # base_link, else the odometry as read, before any bridging): what a map→odom written beside the log's own
    # odom→base_link is computed against, so that a viewer draws the robot at the estimate (:attr:`drawn_odometry`).
    # None: the odometry itself.
    logged_odometry: PoseSeries | None = None

    @property
    def drawn_odometry(self) -> PoseSeries | None:
        """The odometry a viewer of the log draws the robot from (:attr:`logged_odometry`, else :attr:`odometry`):
        bridging a restart or moving a pass onto the map changes :attr:`odometry`, not the log's TF tree."""
        return self.odometry if self.logged_odometry is None else self.logged_odometry

    @property
    def log_path(self) -> str:
        """The log this recording was read from (its own path, unless it is a piece of one)."""
        return self.source_path or self.path

    def continues_piece(self, prev: Recording) -> bool:
        """Whether this is the piece of a log that comes right after ``prev`` (:meth:`take`)."""
        return self.piece > 0 and self.piece == prev.piece + 1 and self.log_path == prev.log_path

    def take(self, start: int, stop: int, path: str, piece: int) -> Recording:
        """Scans start … stop − 1 as piece number ``piece`` of this log, a recording named ``path``, with their
        colours and the poses around them (:meth:`PoseSeries.around`); the log's warnings go with its first piece
        only (once in a map of its pieces)."""
        if stop <= start:
            raise ValueError(f"an empty piece of {self.path}: scans {start} to {stop}")
        t0, t1 = int(self.scans.stamps_ns[start]), int(self.scans.stamps_ns[stop - 1])
        return replace(self, path=path, source_path=self.log_path, piece=piece, scans=self.scans.take(start, stop),
                       odometry=None if self.odometry is None else self.odometry.around(t0, t1),
                       logged_odometry=None if self.logged_odometry is None else self.logged_odometry.around(t0, t1),
                       reference=None if self.reference is None else self.reference.around(t0, t1),
                       colors=None if self.colors is None else self.colors[start:stop],
                       color_valid=None if self.color_valid is None else self.color_valid[start:stop],
                       warnings=list(self.warnings) if piece == 0 else [])

    @property
    def reference_is_odometry(self) -> bool:
        """The reference is the odometry moved rigidly (:attr:`odometry_to_reference`): no independent one."""
        return self.odometry_to_reference is not None


def pose_series(poses: list[Pose2D]) -> PoseSeries | None:
    """Poses as a stamp-sorted PoseSeries (None when there are none)."""
    if not poses:
        return None
    poses = sorted(poses, key=lambda p: p.stamp_ns)
    return PoseSeries(np.array([p.stamp_ns for p in poses], dtype=np.int64),
                      np.array([[p.x, p.y, p.yaw] for p in poses], dtype=np.float64), poses[0].frame_id)


def odometry_frame(tf: TfBuffer, odom: str, base: str) -> str | None:
    """The frame TF odometry is read in: ``odom`` when ``base``'s chain reaches it; else the parent of the first
    edge above ``base`` that moves (a tree that calls it odom_combined, say, above a base_footprint→base_link
    republished on /tf: :meth:`TfBuffer.moves`), or of the first dynamic one where none moves (a robot that
    stood still); None when no dynamic edge is above."""
    if base not in tf.frames:
        return None
    chain = tf.chain(base)
    if odom in chain[1:]:
        return odom
    dynamic = [i for i, child in enumerate(chain[:-1]) if not tf.is_static(child)]
    moving = [i for i in dynamic if tf.moves(chain[i])]
    return chain[(moving or dynamic)[0] + 1] if dynamic else None


def _planar(mat: FloatArray) -> FloatArray:
    """(x, y, yaw) of a 4×4 transform."""
    return np.array([mat[0, 3], mat[1, 3], yaw_of_matrix(mat)])


def _tf_poses(tf: TfBuffer, frame: str, base: str) -> list[Pose2D]:
    """``base``'s pose in ``frame`` (an ancestor) at every stamp of the dynamic edges between them, through static
    edges too, each with the log time of its transform (for the clock check, :func:`on_one_clock`)."""
    chain = tf.chain(base)
    edges = [c for c in chain[:chain.index(frame)] if not tf.is_static(c)]
    if len(edges) == 1:  # one dynamic edge (odom → base_footprint, mounts static): all its samples at once
        return _one_edge_poses(tf, frame, base, edges[0])
    logged: dict[int, int] = {}  # stamp → when the log recorded it
    for c in edges:
        for t, g in zip(tf.stamps(c), tf.log_times(c), strict=True):
            logged.setdefault(t, g)
    poses = []
    for t in sorted(logged):
        try:
            x, y, yaw = _planar(tf.lookup(frame, base, t))
        except TransformError:  # another dynamic edge of the chain has no data near this stamp
            continue
        poses.append(Pose2D(t, logged[t], frame, base, float(x), float(y), float(yaw)))
    return poses


def _one_edge_poses(tf: TfBuffer, frame: str, base: str, edge: str) -> list[Pose2D]:
    """:func:`_tf_poses` where ``edge`` is the one dynamic edge between ``frame`` and ``base``: the lookup's
    products (static edges below it, its sample, static edges above it, base up) taken for all its samples at once."""
    stamps, samples = tf.samples(edge)
    if not stamps.size:
        return []
    t = int(stamps[0])
    parent = tf.chain(edge)[1]
    mats = samples @ tf.lookup(edge, base, t)
    mats = tf.lookup(frame, parent, t) @ mats if parent != frame else mats
    yaw = np.arctan2(mats[:, 1, 0], mats[:, 0, 0])
    return [Pose2D(int(s), int(g), frame, base, float(x), float(y), float(a))
            for s, g, x, y, a in zip(stamps, tf.log_times(edge), mats[:, 0, 3], mats[:, 1, 3], yaw, strict=True)]


def tf_odometry(tf: TfBuffer, odom: str, base: str) -> tuple[list[Pose2D], str | None]:
    """Odometry from the TF tree (DESIGN.md, Inputs: TF odom→base_link): ``base``'s pose in
    :func:`odometry_frame` at every stamp of the dynamic edges between them, through static edges too
    (odom → base_footprint → base_link). And a note when the frame is not ``odom``.
    """
    frame = odometry_frame(tf, odom, base)
    if frame is None:
        return [], None
    return _tf_poses(tf, frame, base), None if frame == odom else odometry_frame_note(frame, odom, base)


def tf_reference(tf: TfBuffer, frames: FramesConfig) -> tuple[list[Pose2D], str | None]:
    """A reference from the TF tree, for a log without a reference topic: ``base``'s pose in ``frames.map`` where a
    dynamic edge lies above the odometry frame (REP 105's map→odom, which a localizer such as AMCL or a SLAM node
    publishes), at every stamp of the dynamic edges between map and base (:func:`_tf_poses`); and a note saying
    where it came from. Nothing where the map frame is not above base, or only static edges join it to the
    odometry frame (that map pose is the odometry moved rigidly)."""
    base, target = frames.base_link, frames.map
    odom = odometry_frame(tf, frames.odom, base)
    if odom is None or odom == target:
        return [], None
    chain = tf.chain(base)
    if target not in chain or chain.index(target) < chain.index(odom):
        return [], None
    if all(tf.is_static(c) for c in chain[chain.index(odom):chain.index(target)]):
        return [], None
    poses = _tf_poses(tf, target, base)
    return poses, (f"reference poses from TF {target}→{base}: no reference topic, so the log's own localizer or "
                   f"SLAM ({target}→{odom}) stands in" if poses else None)


def model_states_note(reader: LogReader) -> list[str]:
    """Why a log whose reference topic is a gazebo_msgs/ModelStates gave no reference pose: none or several of its
    models look like the robot (:func:`~doorbatch.io.decode.robot_model_index`)."""
    topic = reader.roles.topic(Role.REFERENCE)
    if topic is None or reader.topics[topic].msgtype != MODEL_STATES:
        return []
    first = next(iter(reader.raw_messages([topic])), None)
    names = ", ".join(str(n) for n in first.msg.name) if first is not None else ""
    return [f"{topic}: Gazebo's model states hold {names}, and no single one looks like the robot: the log has no "
            "reference (set topics.reference_model)"]


def resolve_base_frame(tf: TfBuffer, frames: FramesConfig) -> tuple[FramesConfig, str | None]:
    """``frames`` with ``base_link`` replaced by the child of the odometry edge (``odom`` → X, the robot's base:
    base_footprint on a TurtleBot whose /tf_static was not recorded) when the TF tree has transforms but not
    the configured base frame, and a note saying so; else ``frames`` unchanged and None."""
    if not tf.frames or frames.base_link in tf.frames:
        return frames, None
    children = sorted(child for parent, child, static in tf.edges() if not static and parent == frames.odom)
    if len(children) != 1:
        return frames, None
    note = (f"the TF tree has no frame {frames.base_link!r}: the robot's base is taken to be {children[0]!r}, the "
            f"child of {frames.odom!r} (set frames.base_link to choose)")
    return frames.model_copy(update={"base_link": children[0]}), note


def missing_laser_tf_hint(tf: TfBuffer, base: str, laser: str | None = None) -> str:
    """How to fix a scan frame with no transform to ``base``: when the TF tree never names the laser's frame
    (a recording started after /tf_static was latched), say what ``io.assume_identity_laser_tf`` does; name
    another base frame when the tree lacks ``base`` itself (the robot's base is the child of its odometry edge,
    e.g. base_footprint); else say what ``io.assume_identity_laser_tf`` does."""
    if laser is not None and tf.frames and laser not in tf.frames:
        return (f"no transform in the log names the laser frame {laser!r}: a recording started after /tf_static was "
                "latched, or a later piece of one split in pieces? doorbatch map borrows the mount from a piece "
                "given with it that has it; --set io.laser_mount=[x,y,z,roll,pitch,yaw] gives the mount; "
                "io.assume_identity_laser_tf=true takes the laser at the base's origin, upright, wrong for any other "
                "mount")
    if tf.frames and base not in tf.frames:
        dynamic = sorted((parent, child) for parent, child, static in tf.edges() if not static)
        guess = next((c for p, c in dynamic if "odom" in p), None) or next(
            (f for f in sorted(tf.frames) if "base" in f), None)
        example = f", e.g. --set frames.base_link={guess}" if guess else ""
        return (f"the TF tree has no frame {base!r} (it has {', '.join(sorted(tf.frames))}): set frames.base_link "
                f"to the robot's base frame{example}")
    return "io.assume_identity_laser_tf=true assumes the laser at the base origin"


def tree_odometry(tf: TfBuffer, odometry: PoseSeries | None, base: str) -> PoseSeries | None:
    """``base``'s pose in the odometry's frame from the TF tree (:func:`_tf_poses`), where the tree has that frame
    above ``base`` with a dynamic edge between them (an odometry topic beside an EKF's odom→base_link on /tf: the
    tree is the EKF's); else None."""
    chain = tf.chain(base) if base in tf.frames else []
    if odometry is None or odometry.frame_id not in chain[1:]:
        return None
    if all(tf.is_static(c) for c in chain[:chain.index(odometry.frame_id)]):
        return None
    return pose_series(_tf_poses(tf, odometry.frame_id, base))


def odometry_frame_note(frame: str, odom: str, base: str) -> str:
    """What a user is told when TF odometry is read in another frame than ``odom``."""
    return f"odometry from TF {frame}→{base}: the TF tree has no frame {odom!r} (set frames.odom to choose another)"


def base_pose_series(poses: list[Pose2D], tf: TfBuffer, base: str) -> PoseSeries | None:
    """Poses of ``base`` (stamp-sorted), from poses of whatever body frame a log gives.

    A pose of frame X (Odometry's ``child_frame_id``: TurtleBot's odom → base_footprint; the odom → X transforms
    of a TF-only log) is composed with X → ``base`` at its stamp when X is on ``base``'s chain in the TF tree
    (an ancestor or a descendant): p_base = p_X ∘ T(X → base), planar part. A pose of ``base``, of an unnamed
    frame, or of a frame the TF tree does not know is taken as the base's own. A pose of a frame the tree knows
    but off ``base``'s chain (another child of odom) is not the robot's: left out.
    """
    on_chain = set(tf.chain(base)) if base in tf.frames else {base}
    # per child frame: None = the base's own pose, True = move it to base, False = not the robot's
    moved: dict[str, bool | None] = {}
    kept: list[Pose2D] = []
    for p in poses:
        child = p.child_frame_id
        if child not in moved:
            own = not child or child == base or child not in tf.frames
            moved[child] = None if own else (child in on_chain or base in tf.chain(child))
        how = moved[child]
        if how is None:
            kept.append(p)
        elif how:
            try:
                x, y, yaw = compose((p.x, p.y, p.yaw), _planar(tf.lookup(child, base, p.stamp_ns,
                                                                                  hold_constant=True)))
            except TransformError:
                continue
            kept.append(replace(p, child_frame_id=base, x=float(x), y=float(y), yaw=float(yaw)))
    return pose_series(kept)


def odometry_poses(odom: list[Pose2D], tf: TfBuffer, odometry_topic: bool, frames: FramesConfig
                   ) -> tuple[list[Pose2D], list[str]]:
    """The odometry a reader collected from its odometry topic; without one, the odometry from TF
    (:func:`tf_odometry`, with the log time of each transform). And the notes for the user.

    A topic whose pose never changes while its twist moves (a base that fills only ``twist``) is dead as a pose:
    the odometry then comes from TF odom→base_link where that moves, else from its twist integrated
    (:func:`~doorbatch.geometry.odometry.integrated_twist`), with a note."""
    if odometry_topic and not _pose_unset_twist_moving(odom):
        return odom, []
    poses, note = tf_odometry(tf, frames.odom, frames.base_link)
    if not odometry_topic:
        return poses, [note] if note else []
    if _moves(poses):
        return poses, [f"the odometry topic's pose never changes while its twist says the base moves (a driver that "
                       f"fills only twist): the odometry is read from TF {frames.odom}→{frames.base_link} instead"]
    return _twist_poses(odom), ["the odometry topic's pose never changes while its twist says the base moves (a "
                                "driver that fills only twist), and no TF odom→base_link moves: the odometry is "
                                "its twist integrated (held between messages)"]


def _pose_unset_twist_moving(odom: Sequence[Pose2D]) -> bool:
    """Whether an odometry topic's pose stays put over the log while its twist is nonzero (in some message)."""
    return len(odom) >= 2 and not _moves(odom) and any(p.vx or p.vy or p.wz for p in odom)


def _moves(poses: Sequence[Pose2D]) -> bool:
    """Whether the poses' x, y or yaw take more than one value."""
    xyz = np.array([[p.x, p.y, p.yaw] for p in poses])
    return len(poses) >= 2 and bool(np.any(xyz != xyz[0]))


def _twist_poses(odom: Sequence[Pose2D]) -> list[Pose2D]:
    """The odometry messages in time order with their poses from their twists, integrated from the first."""
    ordered = sorted(odom, key=lambda p: p.stamp_ns or p.log_time_ns)
    stamps_s = np.array([(p.stamp_ns or p.log_time_ns) * 1e-9 for p in ordered])
    poses = integrated_twist(stamps_s - stamps_s[0], [p.vx for p in ordered], [p.vy for p in ordered],
                             [p.wz for p in ordered])
    return [replace(p, x=float(x), y=float(y), yaw=float(yaw)) for p, (x, y, yaw) in zip(ordered, poses, strict=True)]


def robot_pose_series(odom: list[Pose2D], ref: list[Pose2D], tf: TfBuffer, frames: FramesConfig
                      ) -> tuple[PoseSeries | None, PoseSeries | None]:
    """The odometry (:func:`odometry_poses`) and reference poses of base_link (:func:`base_pose_series`)."""
    return base_pose_series(odom, tf, frames.base_link), base_pose_series(ref, tf, frames.base_link)


def _planar_affine(tf: TfBuffer, base: str, frame: str, stamp_ns: int, assume_identity: bool) -> FloatArray:
    if frame == base:
        return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    try:
        mat = tf.lookup(base, frame, stamp_ns, hold_constant=True)
    except TransformError:
        if assume_identity:
            return np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
        raise
    return np.concatenate([mat[:2, :2], mat[:2, 3:4]], axis=1)


def read_transforms(reader: LogReader, config: DoorbatchConfig) -> TfBuffer:
    """Every transform of an open log (a pass over its TF topics only), buffered so that a lookup at any
    stamp sees the transforms that arrive later in the log too (:func:`buffered_transforms`; its note goes to the
    reader's warnings)."""
    records = [item.record for item in reader.messages([Role.TRANSFORMS]) if isinstance(item.record, Transform)]
    tf, note = buffered_transforms(records, reader.scan_origin_mounts().values(), config)
    if note:
        reader.warnings.append(f"{reader.path}: {note}")
    return tf


def buffered_transforms(transforms: Sequence[Transform], mounts: Iterable[Transform], config: DoorbatchConfig
                        ) -> tuple[TfBuffer, str | None]:
    """A log's transforms (in log order) in a buffer, with the scan-origin ``mounts`` of Foxglove scans
    (:meth:`~doorbatch.io.reader.LogReader.scan_origin_mounts`); and a note where stamps were unset.

    A dynamic edge whose transforms are all stamped 0 (a writer that leaves the stamp unset, as a Foxglove
    FrameTransform without ``timestamp``) would hold one transform at 0, the last logged: each is timed by its log
    time, the only time the edge has (the scans' clock may differ: :func:`on_one_clock` compares the odometry it
    gives with the scans). An edge with some stamps set keeps them all, so that one clock times it (a few zeros
    before a simulator's first /clock collapse into one transform at 0, far from any scan)."""
    edges: dict[str, list[int]] = {}
    for k, t in enumerate(transforms):
        if not t.static:
            edges.setdefault(t.child, []).append(k)
    timed = list(transforms)
    moved: dict[str, int] = {}
    for child, ks in edges.items():
        if any(transforms[k].stamp_ns != 0 or transforms[k].log_time_ns <= 0 for k in ks):
            continue
        for k in ks:
            timed[k] = replace(transforms[k], stamp_ns=transforms[k].log_time_ns)
        moved[child] = len(ks)
    tf = TfBuffer(int(config.io.tf_extrapolation_limit_s * 1e9))
    for t in (*timed, *mounts):
        tf.add(t)
    note = None
    if moved:
        which = ", ".join(f"{transforms[edges[c][0]].parent}→{c} ({n} of {len(edges[c])})" for c, n in moved.items())
        note = f"transforms with header stamp 0 (unset): timed by their log time: {which}"
    return tf, note


@dataclass(frozen=True)
class OneClock:
    """Scans (in stamp order) and poses on one time line; ``header_stamps_ns`` are the scans' stamps as logged
    (what per-scan side messages such as beam colours carry), ``notes`` say what was changed."""

    scans: list[Scan]
    odom: list[Pose2D]
    ref: list[Pose2D]
    header_stamps_ns: list[int]
    notes: list[str]
    log_clock: LogClock = field(default_factory=LogClock)  # the recorder's clock against the scans' stamps


def clock_lags_s(scan_stamps_ns: Sequence[int], scan_log_ns: Sequence[int], odom_stamps_ns: Sequence[int],
                 odom_log_ns: Sequence[int], mismatch_s: float) -> tuple[float, float] | None:
    """The median (header stamp − log time) of scans and of odometry, in s, when they differ by more than
    ``mismatch_s`` (two clocks), else None. Unset stamps (0) and unknown log times (0) are left out. Odometry
    from TF has the log times of its transforms (:func:`tf_odometry`)."""
    def lag(stamps: Sequence[int], logged: Sequence[int]) -> float | None:
        d = [t - g for t, g in zip(stamps, logged, strict=True) if t != 0 and g != 0]
        return float(np.median(d)) / 1e9 if d else None

    a, b = lag(scan_stamps_ns, scan_log_ns), lag(odom_stamps_ns, odom_log_ns)
    return (a, b) if a is not None and b is not None and abs(a - b) > mismatch_s else None


def clock_steps(stamps_ns: Sequence[int], log_ns: Sequence[int], step_s: float) -> list[tuple[int, float]]:
    """Steps of a topic's header stamps against the recorder's clock (message index, step in s): consecutive
    messages whose stamps lie more than ``step_s`` further apart (or nearer, or backwards) than their median
    interval while their log times lie the usual interval apart, and whose stamps keep to the stepped time over
    the five intervals on either side (a clock that was set, as NTP sets one). A message that arrived late (its
    log time out of step), a dropout (both out of step), a paused simulator (its log times out of step) or
    messages logged in another order than their stamps is none. Log times that do not keep a rate themselves
    (a recorder that received in bursts, or logged whole seconds) cannot tell a step: none is found. Unset
    stamps (0) are left out."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    g = np.asarray(log_ns, dtype=np.int64)
    keep = np.flatnonzero((t != 0) & (g != 0))
    if keep.size < 12:
        return []
    ds, dl = np.diff(t[keep]) / 1e9, np.diff(g[keep]) / 1e9
    med_ds, med_dl = float(np.median(ds)), float(np.median(dl))
    regular = np.abs(dl - med_dl) <= step_s / 2
    if med_dl <= 0.0 or regular.mean() < 0.9:
        return []
    pace = med_ds / med_dl  # a simulator's sim time runs at its real-time factor
    jump = ds - pace * dl
    out = []
    for i in np.flatnonzero((np.abs(ds - med_ds) > step_s) & regular).tolist():
        if i < 5 or i + 6 > jump.size:  # too near an end to see the stamps keep to it
            continue
        if abs(float(jump[i - 5:i + 6].sum())) > step_s / 2:  # not undone by the intervals about it
            out.append((int(keep[i + 1]), float(jump[i])))
    return out


def clock_restarts(stamps_ns: Sequence[int], log_ns: Sequence[int], back_s: float) -> list[tuple[int, float]]:
    """Where a topic's header stamps go back by more than ``back_s`` and stay back while the recorder's clock goes
    on (message index, step in s): a simulator relaunched within one recording (its sim time starting at 0 again).
    Stay back: the next five stamps lie below the one before the step, so that one message stamped late or logged
    out of order is none (nor a step with fewer than five after it). Unset stamps (0) and unknown log times are left
    out."""
    t = np.asarray(stamps_ns, dtype=np.int64)
    g = np.asarray(log_ns, dtype=np.int64)
    keep = np.flatnonzero((t != 0) & (g != 0))
    t, g = t[keep], g[keep]
    out = []
    for i in np.flatnonzero((np.diff(t) < -back_s * 1e9) & (np.diff(g) >= 0)).tolist():
        if i + 6 <= t.size and np.all(t[i + 1:i + 6] < t[i] - back_s * 1e9):  # five after it, not a late last one
            out.append((int(keep[i + 1]), float(t[i + 1] - t[i]) / 1e9))
    return out


def clock_ahead_s(scan_stamps_ns: Sequence[int], scan_log_ns: Sequence[int], odom_stamps_ns: Sequence[int],
                  odom_log_ns: Sequence[int], warn_s: float, mismatch_s: float) -> float | None:
    """How far the scans' median (stamp − log time) exceeds the odometry's, in s, over the log time both span,
    when by more than ``warn_s`` and at most ``mismatch_s`` (beyond it, :func:`clock_lags_s`: two clocks); else
    None, and None when the scans' stamps do not keep the recorder's pace within 1 % (a simulator's sim time,
    whose gap to the log time drifts). Latency only makes a stamp earlier than its log time, so scans stamped
    later than their odometry were stamped by a clock ahead."""
    def set_pairs(stamps: Sequence[int], logged: Sequence[int]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        a, b = np.asarray(stamps, dtype=np.int64), np.asarray(logged, dtype=np.int64)
        ok = (a != 0) & (b != 0)
        return a[ok], b[ok]

    (ts, gs), (to, go) = set_pairs(scan_stamps_ns, scan_log_ns), set_pairs(odom_stamps_ns, odom_log_ns)
    if ts.size < 2 or to.size < 2 or gs[-1] == gs[0]:
        return None
    if abs((ts[-1] - ts[0]) / (gs[-1] - gs[0]) - 1.0) > 0.01:
        return None
    lo, hi = max(gs.min(), go.min()), min(gs.max(), go.max())
    in_s, in_o = (gs >= lo) & (gs <= hi), (go >= lo) & (go <= hi)
    if not in_s.any() or not in_o.any():
        return None
    ahead = float(np.median(ts[in_s] - gs[in_s]) - np.median(to[in_o] - go[in_o])) / 1e9
    return ahead if warn_s < ahead <= mismatch_s else None


def unset_stamps(stamps_ns: Sequence[int]) -> npt.NDArray[np.bool_]:
    """Which header stamps (one topic, in log order) are unset: 0, unless the clock starts there. Gazebo's sim
    time starts at 0 s, so the last 0 before any set stamp, when the first set stamp after it lies within
    max(1 s, 10 median intervals of the set stamps), is that clock's first instant; every other 0 (several
    before the first /clock, a driver that leaves the stamp unset, a 0 in the middle of a run) is unset."""
    s = np.asarray(stamps_ns, dtype=np.int64)
    zero: npt.NDArray[np.bool_] = s == 0
    if not zero.any() or zero.all():
        return zero
    first_set = int(np.argmax(~zero))
    unset = zero.copy()
    if first_set > 0:  # leading zeros: the last of them may be the clock's start
        steps = np.diff(np.sort(s[~zero]))
        limit = max(1e9, 10.0 * float(np.median(steps[steps > 0]))) if (steps > 0).any() else 1e9
        unset[first_set - 1] = abs(int(s[first_set])) > limit
    return unset


def _log_timed(records: list[R], every: bool, clock: LogClock | None = None) -> list[R]:
    """The records with their log time as stamp: ``every`` one, else those whose stamp is unset
    (:func:`unset_stamps`), put on the scans' clock by ``clock`` (sim time: a gazebo_msgs/ModelStates has no
    header)."""
    unset = unset_stamps([r.stamp_ns for r in records])
    return [replace(r, stamp_ns=r.log_time_ns) if every
            else replace(r, stamp_ns=r.log_time_ns if clock is None else clock.stamp_at(r.log_time_ns)) if u
            else r for r, u in zip(records, unset, strict=True)]


def scans_clock(scans: Sequence[Scan], mismatch_s: float) -> LogClock:
    """The :class:`~doorbatch.io.log_clock.LogClock` of the scans with a set stamp and a log time."""
    unset = unset_stamps([sc.stamp_ns for sc in scans])
    pairs = [(sc.log_time_ns, sc.stamp_ns) for sc, u in zip(scans, unset, strict=True) if sc.log_time_ns and not u]
    return LogClock.of_pairs([g for g, _ in pairs], [t for _, t in pairs], mismatch_s)


def on_one_clock(scans: list[Scan], odom: list[Pose2D], ref: list[Pose2D], io: IoConfig) -> OneClock:
    """Scans and poses whose header stamps can be put on one time line, in stamp order, and notes saying what
    was done. A header stamp of 0 is unset (:func:`unset_stamps`: not where a clock starts at 0): the message's
    log time stands in, on the scans' clock (:func:`scans_clock`). Scans and odometry whose median
    (stamp − log time) differ by more than ``io.clock_mismatch_s`` are on two clocks (a driver stamping with its
    device's clock), and scan or odometry stamps that step (:func:`clock_steps`) follow a clock that was set:
    either way every scan and pose is timed by its log time, the recorder's one clock. Scans stamped ahead of
    their odometry (:func:`clock_ahead_s`) are told of. Scans that arrived out of stamp order are sorted (bags
    record arrival order; the stamp is the measurement's time).
    """
    notes: list[str] = []
    header = [s.stamp_ns for s in scans]
    mismatch_s = io.clock_mismatch_s
    timing: Timing = ([s.stamp_ns for s in scans], [s.log_time_ns for s in scans],
                      [p.stamp_ns for p in odom], [p.log_time_ns for p in odom])
    lags = clock_lags_s(*timing, mismatch_s)
    for name, records in (("scans", scans), ("odometry poses", odom), ("reference poses", ref)):
        unset = int(unset_stamps([r.stamp_ns for r in records]).sum())
        if unset:
            notes.append(f"{unset} of {len(records)} {name} have header stamp 0 (unset) or no header: timed by "
                         f"their log time")
    if lags is not None:
        notes.append(f"scan and odometry header stamps are on different clocks (median stamp − log time "
                     f"{lags[0]:+.3f} s and {lags[1]:+.3f} s): every scan and pose is timed by its log time")
    stepped, note = clock_fault(timing, io) if lags is None else (False, None)
    notes += [note] if note else []
    every = lags is not None or stepped
    clock = scans_clock(scans, mismatch_s)
    scans, odom, ref = _log_timed(scans, every, clock), _log_timed(odom, every, clock), _log_timed(ref, every, clock)
    stamps = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    back = int(np.count_nonzero(np.diff(stamps) < 0))
    if back:
        order = np.argsort(stamps, kind="stable")
        scans, header = [scans[i] for i in order], [header[i] for i in order]
        notes.append(f"scan header stamps go backwards {back} time(s) in log order: scans sorted by stamp")
    return OneClock(scans, odom, ref, header, notes, LogClock() if every else clock)


Timing = tuple[Sequence[int], Sequence[int], Sequence[int], Sequence[int]]  # scan stamps, log times; odometry's


def clock_fault(timing: Timing, io: IoConfig) -> tuple[bool, str | None]:
    """For scans and odometry on one clock (:func:`clock_lags_s` found two none): whether their header stamps step
    (:func:`clock_steps`; every scan and pose is then timed by its log time), with its warning; else the warning
    for scans stamped ahead of their odometry (:func:`clock_ahead_s`, unless ``io.scan_time_offset_s`` is set);
    (False, None) when neither."""
    restarts = {name: found for name, found in (("scan", clock_restarts(*timing[:2], io.clock_mismatch_s)),
                                                ("odometry", clock_restarts(*timing[2:], io.clock_mismatch_s)))
                if found}
    if restarts:
        return True, _clock_steps_note(restarts, timing[1][0] if timing[1] else 0, timing, restarted=True)
    steps = {name: found for name, found in (("scan", clock_steps(*timing[:2], io.clock_step_s)),
                                             ("odometry", clock_steps(*timing[2:], io.clock_step_s))) if found}
    if steps:
        return True, _clock_steps_note(steps, timing[1][0] if timing[1] else 0, timing)
    if not io.scan_time_offset_s and (ahead := clock_ahead_s(*timing, io.clock_ahead_warn_s, io.clock_mismatch_s)):
        return False, _clock_ahead_note(ahead)
    return False, None


def _clock_steps_note(steps: dict[str, list[tuple[int, float]]], first_log_ns: int, timing: Timing,
                      restarted: bool = False) -> str:
    """The warning for header stamps that step (:func:`clock_steps`) or start again (:func:`clock_restarts`,
    ``restarted``), by topic: the first step's size and when."""
    parts = []
    for name, found in steps.items():
        index, step = found[0]
        logged = (timing[1] if name == "scan" else timing[3])[index]
        parts.append(f"{name} header stamps {'go back' if restarted else 'step'} by {step:+.2f} s against the "
                     f"recorder's clock {(logged - first_log_ns) / 1e9:.1f} s into the log"
                     + (f" ({len(found)} steps)" if len(found) > 1 else ""))
    why = ("a simulator relaunched within the recording, its time starting again?" if restarted
           else "a clock that was set (an NTP step?)")
    return f"{'; '.join(parts)}: {why}; every scan and pose is timed by its log time instead"


def _clock_ahead_note(ahead_s: float) -> str:
    """The warning for scans stamped ahead of their odometry (:func:`clock_ahead_s`), with the setting that
    takes it out."""
    return (f"scan header stamps lie {ahead_s:.3f} s later against their log times than the odometry's (medians): "
            f"latency only makes a stamp earlier, so the laser's clock runs ahead of the odometry's and each scan "
            f"would be placed where the robot was {ahead_s:.3f} s later; if so, --set "
            f"io.scan_time_offset_s={-ahead_s:.3f}")


def scan_colors(colors: Sequence[BeamColors], header_stamps_ns: Sequence[int], log_times_ns: Sequence[int],
                tolerance_ns: int) -> list[BeamColors | None]:
    """Each scan's colours: the message with the scan's header stamp; for a scan with none (its stamp unset, or
    on another clock than the colours': a laser driver's own), the colour message logged nearest to it within
    ``tolerance_ns`` that is no other scan's by stamp (a scan whose own colour message was dropped takes none)."""
    by_stamp = {c.stamp_ns: c for c in colors if c.stamp_ns != 0}
    claimed = set(header_stamps_ns) - {0}
    by_log = sorted((c for c in colors if c.stamp_ns == 0 or c.stamp_ns not in claimed), key=lambda c: c.log_time_ns)
    times = np.array([c.log_time_ns for c in by_log], dtype=np.int64)
    out: list[BeamColors | None] = []
    for stamp, logged in zip(header_stamps_ns, log_times_ns, strict=True):
        if stamp != 0 and stamp in by_stamp:
            out.append(by_stamp[stamp])
            continue
        k = int(np.argmin(np.abs(times - logged))) if times.size else -1
        out.append(by_log[k] if k >= 0 and abs(int(times[k]) - logged) <= tolerance_ns else None)
    return out


def colors_note(found: Sequence[BeamColors | None], beams: Sequence[int], topic: str) -> str | None:
    """A warning when under half the scans have a colour message with one point per beam: how many have none
    and how many one of another length (the em stage's colour then rests on the rest, or on nothing)."""
    missing = sum(c is None for c in found)
    other = [(c.rgb.shape[0], n) for c, n in zip(found, beams, strict=True) if c is not None and c.rgb.shape[0] != n]
    if 2 * (missing + len(other)) <= len(found):
        return None
    parts = [f"{missing} have no colour message on {topic} (none with their header stamp, none logged within "
             "io.stamp_tolerance_s)"] if missing else []
    parts += [f"{len(other)} have one of another length (first: {other[0][0]} points for {other[0][1]} beams)"]\
        if other else []
    return (f"of {len(found)} scans, {' and '.join(parts)}: their beams have no colour"
            + (", so doorbatch map's default stages leave out the em stage" if missing + len(other) == len(found)
               else ""))


def load_recording(path: Path, config: DoorbatchConfig | None = None, with_colors: bool = False,
                   borrowed_mounts: Sequence[Transform] = (), no_return_code: bool = True) -> Recording:
    """Read the scans, odometry, reference poses (and beam colors) of a log into arrays.

    Transforms are read first (a pass over the TF topics only), so that each scan's laser→base_link
    transform is known at its own stamp even when the TF arrives later in the log. ``borrowed_mounts``: static
    transforms of another log of the same robot, added where the log's own tree does not take the laser to
    base_link, for the frames it lacks (:func:`load_passes`). ``no_return_code``: look for the no-return code of
    scans that state no range_max (:func:`with_no_return_code`; :func:`load_passes` looks over all passes at once).

    Raises:
        LaserMountError: no transform from the laser frame to base_link.
        LogContentError: no scans.
        LogReadError: the log cannot be read.
    """
    config = config or DoorbatchConfig()
    roles = [Role.SCAN, Role.ODOMETRY, Role.REFERENCE] + ([Role.COLORS] if with_colors else [])
    scans: list[Scan] = []
    odom: list[Pose2D] = []
    ref: list[Pose2D] = []
    colors: list[BeamColors] = []
    with open_log(path, config) as reader:
        tf = read_transforms(reader, config)
        scan_topic = reader.roles.topic(Role.SCAN)
        if scan_topic is None:
            raise LogContentError("no sensor_msgs/LaserScan topic: doorbatch needs a 2D laser scan", path=path)
        for item in reader.messages(roles):
            rec = item.record
            if item.role is Role.SCAN and isinstance(rec, Scan):
                scans.append(rec)
            elif item.role is Role.ODOMETRY and isinstance(rec, Pose2D):
                odom.append(rec)
            elif item.role is Role.REFERENCE and isinstance(rec, Pose2D):
                ref.append(rec)
            elif item.role is Role.COLORS and isinstance(rec, BeamColors):
                colors.append(rec)
        borrowed = (borrow_mounts(tf, borrowed_mounts) if scans and borrowed_mounts
                    and not tf.can_transform(config.frames.base_link, scans[0].frame_id) else None)
        mounted = None
        if scans and config.io.laser_mount is not None and config.io.laser_mount_replaces_tf:
            tf.add(configured_mount(config, scans[0].frame_id))  # a static edge into the laser replaces the log's
            mounted = (f"io.laser_mount {list(config.io.laser_mount)} replaces the log's transform into the laser "
                       f"frame {scans[0].frame_id!r} (io.laser_mount_replaces_tf)")
        elif (scans and config.io.laser_mount is not None
                and not tf.can_transform(config.frames.base_link, scans[0].frame_id)):
            tf.add(configured_mount(config, scans[0].frame_id))
            mounted = (f"no transform in the log takes the laser frame {scans[0].frame_id!r} to "
                       f"{config.frames.base_link!r}: io.laser_mount {list(config.io.laser_mount)} is used")
        frames, base_note = resolve_base_frame(tf, config.frames)
        odom, odom_notes = odometry_poses(odom, tf, reader.roles.topic(Role.ODOMETRY) is not None, frames)
        notes = [f"{path}: {n}" for n in (*odom_notes, borrowed, mounted) if n]
        notes += model_states_note(reader) if not ref else []
        if reader.roles.topic(Role.REFERENCE) is None:
            ref, note = tf_reference(tf, frames)
            notes += [note] if note else []
        timed = without_repeated_scans(on_one_clock(scans, odom, ref, config.io))
        offset_ns = round(config.io.scan_time_offset_s * 1e9)
        scans = [replace(s, stamp_ns=s.stamp_ns + offset_ns) for s in timed.scans] if offset_ns else timed.scans
        odometry, reference = robot_pose_series(timed.odom, timed.ref, tf, frames)
        logged = tree_odometry(tf, odometry, frames.base_link) or odometry
        odometry, jump_note, bridge = bridged_odometry(odometry, config)
        notes += [f"{path}: {jump_note}"] if jump_note else []
        warnings = [*reader.warnings, *(f"{path}: {n}" for n in timed.notes), *([base_note] if base_note else []),
                    *notes]
        image_topic, colors_topic = reader.roles.topic(Role.IMAGE), reader.roles.topic(Role.COLORS)
        camera = image_topic is not None and reader.roles.topic(Role.CAMERA_INFO) is not None
    if not scans:
        raise LogContentError("scan topic has no messages", path=path, topic=scan_topic)
    if lost := lost_times_note([s.stamp_ns for s in scans]):
        raise LogContentError(lost, path=path, topic=scan_topic)
    base = frames.base_link
    try:
        affines = np.stack([_planar_affine(tf, base, s.frame_id, s.stamp_ns, config.io.assume_identity_laser_tf)
                            for s in scans])
    except TransformError as err:
        raise LaserMountError(f"{err.reason} ({missing_laser_tf_hint(tf, base, scans[0].frame_id)})", path=path,
                              topic=scan_topic) from err
    range_min, range_max, note = usable_range_limits(np.array([s.range_min for s in scans]),
                                                     np.array([s.range_max for s in scans]))
    code_note = None
    if no_return_code:
        range_max, code_note = with_no_return_code([s.ranges for s in scans], range_max, config)
    warnings += [n for n in (note, code_note) if n]
    ranges = [s.ranges for s in scans]
    if config.io.veiling_min_angle_deg > 0.0:  # before deskewing: the test reads the fan as the laser measured it
        ranges = [np.where(veiling_mask(r, s.angle_increment, math.radians(config.io.veiling_min_angle_deg),
                                        config.io.veiling_window, float(lo), float(hi)), np.float32(np.nan),
                           r).astype(np.float32)
                  for r, s, lo, hi in zip(ranges, scans, range_min, range_max, strict=True)]
    stamps_ns = np.array([s.stamp_ns for s in scans], dtype=np.int64)
    sources: list[npt.NDArray[np.intp] | None] = []
    sweep = float(np.median([s.sweep_s for s in scans]))
    period_s = float(np.median(np.diff(stamps_ns))) / 1e9 if len(scans) > 1 else math.inf
    if no_sweep := no_sweep_note(sweep, period_s):
        warnings.append(f"{path}: the laser's {no_sweep}")
    elif config.io.deskew and odometry is not None and sweep > 0.0:
        warnings += [f"{path}: {n}" for n in [end_of_sweep_note(scans, sweep)] if n]
        ranges, sources = deskewed_scans(ranges, stamps_ns, [s.time_increment_s for s in scans],
                                          [s.angle_min for s in scans], [s.angle_increment for s in scans],
                                          range_min, range_max, affines, odometry.stamps_ns, odometry.poses)
    scan_set = ScanSet(
        stamps_ns=stamps_ns,
        ranges=ranges,
        angle_min=np.array([s.angle_min for s in scans]),
        angle_increment=np.array([s.angle_increment for s in scans]),
        range_min=range_min,
        range_max=range_max,
        laser_to_base=affines,
        frame_id=scans[0].frame_id,
    )
    aligned = None
    valid = None
    if with_colors and colors:
        found = scan_colors(colors, timed.header_stamps_ns, [s.log_time_ns for s in scans],
                            int(config.io.stamp_tolerance_s * 1e9))
        aligned = [_aligned_colors(c, s.ranges.shape[0]) for s, c in zip(scans, found, strict=True)]
        if note := colors_note(found, [s.ranges.shape[0] for s in scans], colors_topic or "the colour topic"):
            warnings.append(f"{path}: {note}")
        if not any(a.shape[0] for a in aligned):
            aligned = None
    elif with_colors and camera:  # no /scan_colors: project the scan into the camera images
        from doorbatch.io.camera_colors import camera_beam_colors

        aligned, valid, camera_notes = camera_beam_colors(path, scans, tf, config, timed.header_stamps_ns)
        warnings += [f"{path}: {n}" for n in camera_notes]
    elif with_colors and image_topic is not None:
        from doorbatch.io.camera_colors import COLORLESS

        warnings.append(f"{path}: images on {image_topic} but no CameraInfo to project the scans into them; "
                        f"{COLORLESS}")
    if aligned is not None and any(src is not None for src in sources):  # colours follow their beams
        aligned, valid = moved_beam_colors(aligned, valid, sources)
    deskewed = sum(src is not None for src in sources)
    if (odometry is not None and deskewed < 0.5 * len(scans) and not no_sweep
            and (smear := sweep_smear_m(sweep, odometry.stamps_ns, odometry.poses, config.io.sweep_check_range_m,
                                        config.io.sweep_check_quantile)) > config.io.sweep_smear_warn_m):
        why = "io.deskew is off" if not config.io.deskew else f"the odometry spans {deskewed} of {len(scans)} sweeps"
        warnings.append(f"{path}: the laser takes {1e3 * sweep:.0f} ms per sweep (time_increment) while the robot "
                        f"moves: a beam end point at {config.io.sweep_check_range_m:g} m moves {smear:.2f} m (the "
                        f"{config.io.sweep_check_quantile:.0%} quantile of speed and turn rate) during one scan, "
                        f"and the scans are not deskewed ({why}): expect doubled walls in the map and a less exact "
                        "pose")
    repeats = odometry_to_reference(reference, odometry, scan_set.stamps_ns, config)
    if repeats is not None:
        warnings.append(f"{path}: the reference poses are the odometry moved rigidly (within "
                        f"{config.io.reference_repeats_odometry_m} m and {config.io.reference_repeats_odometry_deg}°): "
                        "no independent reference (a raw CARMEN log's laser poses are its odometry; a corrected log's "
                        "odometry was replaced by its corrected poses)")
    return Recording(str(path), scan_set, odometry, reference, aligned, warnings, valid, repeats,
                     timed.log_clock, tuple(tf.static_transforms()), odometry_bridge=bridge,
                     logged_odometry=None if logged is odometry else logged)


def no_sweep_note(sweep_s: float, period_s: float) -> str | None:
    """Why a sweep (time_increment × beams) longer than ``SWEEP_OVER_PERIOD`` scan periods is not deskewed (rotating
    lasers sweep within a period: a driver wrote something else there), else None."""
    if not sweep_s > period_s * SWEEP_OVER_PERIOD:
        return None
    return (f"time_increment × beams is {1e3 * sweep_s:.0f} ms, longer than the scan period ({1e3 * period_s:.0f} ms): "
            "a driver that wrote something else there; the scans are not deskewed")


def end_of_sweep_note(scans: Sequence[Scan], sweep_s: float) -> str | None:
    """A warning when the scans reach the log sooner after their stamp than their sweep lasts (median over the
    scans, more than 0 and under half the sweep): a scan stamped at its first beam cannot be recorded before its
    last, so the driver probably stamps the sweep's end, and deskewing (which takes the stamp as the first beam's
    time, as sensor_msgs/LaserScan defines it) would bend the scans the wrong way. Log times equal to the stamps
    (a converter's) tell nothing."""
    lag_s = float(np.median([s.log_time_ns - s.stamp_ns for s in scans])) / 1e9
    if not 0.0 < lag_s < 0.5 * sweep_s:
        return None
    return (f"the scans reach the log {1e3 * lag_s:.0f} ms after their stamps, sooner than their "
            f"{1e3 * sweep_s:.0f} ms sweep ends: the laser driver probably stamps the end of each sweep, where "
            "LaserScan's stamp is its first beam; if so, --set io.scan_time_offset_s="
            f"{-sweep_s:.3f} puts the stamps there (deskewing otherwise bends each scan the wrong way)")


def moved_beam_colors(colors: list[npt.NDArray[np.uint8]], valid: list[npt.NDArray[np.bool_]] | None,
                      sources: Sequence[npt.NDArray[np.intp] | None]
                      ) -> tuple[list[npt.NDArray[np.uint8]], list[npt.NDArray[np.bool_]] | None]:
    """Per-beam colours (and their validity) moved with deskewed beams: fan angle j takes the colour of the measured
    beam ``sources[i][j]`` (−1: none, colour 0 and invalid); a scan without sources is left as it was."""

    def moved(values: npt.NDArray[Any], src: npt.NDArray[np.intp] | None, none: Any) -> npt.NDArray[Any]:
        if src is None:
            return values
        return np.where((src >= 0).reshape(-1, *[1] * (values.ndim - 1)), values[np.maximum(src, 0)], none)

    out_colors = [moved(c, src, 0).astype(np.uint8) for c, src in zip(colors, sources, strict=True)]
    out_valid = None if valid is None else [moved(v, src, False) for v, src in zip(valid, sources, strict=True)]
    return out_colors, out_valid


def without_repeated_scans(timed: OneClock) -> OneClock:
    """``timed`` without the scans that repeat the one before them (same stamp, same ranges: bags merged, a topic
    recorded twice), with a note; the map would integrate each copy as new evidence."""
    scans = timed.scans
    keep = [k for k in range(len(scans)) if not k or scans[k].stamp_ns != scans[k - 1].stamp_ns
            or not np.array_equal(scans[k].ranges, scans[k - 1].ranges, equal_nan=True)]
    if len(keep) == len(scans):
        return timed
    note = (f"{len(scans) - len(keep)} of {len(scans)} scans repeat the one before them (same stamp and ranges: "
            "merged bags, a topic recorded twice): each is read once")
    return replace(timed, scans=[scans[k] for k in keep], header_stamps_ns=[timed.header_stamps_ns[k] for k in keep],
                   notes=[*timed.notes, note])


def lost_times_note(stamps_ns: Sequence[int]) -> str | None:
    """Why scans whose stamps (header, or log time where unset) take fewer distinct values than half their number
    cannot be placed in time, else None (a few repeats are a merge's duplicates; this is no clock)."""
    distinct = len(set(stamps_ns))
    if len(stamps_ns) < 10 or distinct >= 0.5 * len(stamps_ns):
        return None
    return (f"{len(stamps_ns)} scans carry only {distinct} distinct stamp(s), header and log time alike (first "
            f"{stamps_ns[0]} ns): their times are lost (a converter that stamped them from a field that is 0, e.g. "
            "orebro's CARMEN ipc_timestamp); re-stamp the log, or read the CARMEN log itself, whose stamps doorbatch "
            "synthesizes")


def bridged_odometry(odometry: PoseSeries | None, config: DoorbatchConfig
                     ) -> tuple[PoseSeries | None, str | None, FloatArray | None]:
    """The odometry with its restarts (:func:`~doorbatch.geometry.odometry.odometry_jumps`: a driver that restarted
    at zero) and its set poses (:func:`~doorbatch.geometry.odometry.odometry_teleports`) bridged, a note naming them
    (a localizer or scan matcher fed the jump would take it as motion), and the motion B bridging applied to the last
    pose (bridged = B ⊕ raw; None where nothing was bridged)."""
    if odometry is None:
        return None, None, None
    io = config.io
    restarts = odometry_jumps(odometry.poses, io.odometry_jump_min_m, math.radians(io.odometry_jump_min_deg),
                              io.odometry_restart_at_zero_m, io.odometry_restart_steps)
    teleports = np.setdiff1d(odometry_teleports(odometry.stamps_ns / 1e9, odometry.poses, io.odometry_jump_min_m,
                                                io.odometry_teleport_steps), restarts)
    if not restarts.size and not teleports.size:
        return odometry, None, None
    t0 = int(odometry.stamps_ns[0])

    def said(jumps: npt.NDArray[np.intp]) -> str:
        steps = relative(odometry.poses[jumps - 1], odometry.poses[jumps])
        each = ", ".join(f"{(int(odometry.stamps_ns[i]) - t0) / 1e9:.1f} s ({math.hypot(s[0], s[1]):.2f} m, "
                         f"{math.degrees(s[2]):.0f}°)" for i, s in zip(jumps[:5], steps[:5], strict=True))
        return f"at {each}{f' and {jumps.size - 5} more' if jumps.size > 5 else ''} after its start"

    notes = []
    if restarts.size:
        notes.append(f"the odometry jumps back to (0, 0) {restarts.size} time(s) ({said(restarts)}: a driver that "
                     "restarted)")
    if teleports.size:
        notes.append(f"the odometry jumps elsewhere within a message period {teleports.size} time(s) "
                     f"({said(teleports)}: a pose set from outside, e.g. an EKF's set_pose)")
    note = ("; ".join(notes) + ": each jump is taken out, the odometry after it continuing from the pose before "
            "(io.odometry_jump_min_m, _min_deg, io.odometry_restart_at_zero_m, _restart_steps, _teleport_steps)")
    poses = bridged_jumps(odometry.poses, np.union1d(restarts, teleports))
    return replace(odometry, poses=poses), note, compose(poses[-1], inverse(odometry.poses[-1]))


def configured_mount(config: DoorbatchConfig, laser_frame: str) -> Transform:
    """``io.laser_mount`` (x, y, z, roll, pitch, yaw of the laser in base_link) as a static transform
    base_link → ``laser_frame``; R = Rz(yaw)·Ry(pitch)·Rx(roll), ROS's fixed-axis RPY."""
    from scipy.spatial.transform import Rotation

    assert config.io.laser_mount is not None
    x, y, z, roll, pitch, yaw = config.io.laser_mount
    return Transform(0, config.frames.base_link, laser_frame, np.array([x, y, z], dtype=np.float64),
                     Rotation.from_euler("xyz", [roll, pitch, yaw]).as_quat(), static=True)


def borrow_mounts(tf: TfBuffer, mounts: Sequence[Transform]) -> str | None:
    """Add to ``tf`` the static ``mounts`` into frames it has no transform into, and say which (None: none).

    One recording split in pieces (rosbag2's ``--max-bag-duration``, ``rosbag record --split``) holds the latched
    /tf_static in its first piece only: the later pieces name no laser mount."""
    children = {child for _, child, _ in tf.edges()}
    added = [m for m in mounts if m.child not in children]
    for m in added:
        tf.add(m)
    if not added:
        return None
    return ("its TF tree does not take the laser to the base: the static transforms of another pass of the robot "
            f"are used for {', '.join(f'{m.parent}→{m.child}' for m in added)} (one recording split in pieces "
            "keeps /tf_static in its first)")


def load_passes(paths: Sequence[Path], config: DoorbatchConfig, with_colors: bool = False) -> list[Recording]:
    """The logs of one robot, each a pass (``doorbatch map``), as :func:`load_recording` reads them; a pass whose
    own transforms do not take its laser to base_link borrows the static transforms (sensor mounts) of the
    passes that have them, for the frames it lacks (:func:`borrow_mounts`), the first pass's first.

    Raises:
        LaserMountError: a pass whose laser no pass's transforms reach; as :func:`load_recording` otherwise.
    """
    # the identity mount (io.assume_identity_laser_tf) only for a pass that no other pass lends one
    strict = config.model_copy(update={"io": config.io.model_copy(update={"assume_identity_laser_tf": False})})
    loaded: dict[int, Recording] = {}
    missing: list[int] = []
    mounts: dict[str, Transform] = {}
    for i, path in enumerate(paths):
        try:
            rec = load_recording(Path(path), strict, with_colors, tuple(mounts.values()), no_return_code=False)
        except LaserMountError:
            missing.append(i)  # perhaps a later pass has its mount
            continue
        loaded[i] = rec
        for m in rec.mounts:
            mounts.setdefault(m.child, m)
    for i in missing:
        loaded[i] = load_recording(Path(paths[i]), config, with_colors, tuple(mounts.values()), no_return_code=False)
    return with_shared_no_return_code([loaded[i] for i in range(len(paths))], config)


def with_shared_no_return_code(recordings: Sequence[Recording], config: DoorbatchConfig) -> list[Recording]:
    """The passes with the no-return code their scans that state no range_max show together
    (:func:`with_no_return_code` over all of them: one laser), and its warning in each pass it changes."""
    range_max = np.concatenate([r.scans.range_max for r in recordings]) if recordings else np.zeros(0)
    coded, note = with_no_return_code([x for r in recordings for x in r.scans.ranges], range_max, config)
    out, start = [], 0
    for rec in recordings:
        stop = start + len(rec.scans)
        if note and np.isposinf(rec.scans.range_max).any():  # a pass with scans that state none
            together = f"the {len(recordings)} passes together: " if len(recordings) > 1 else ""
            rec = replace(rec, scans=replace(rec.scans, range_max=coded[start:stop]),
                          warnings=[*rec.warnings, f"{rec.path}: {together}{note}"])
        out.append(rec)
        start = stop
    return out


def odometry_to_reference(reference: PoseSeries | None, odometry: PoseSeries | None,
                          stamps_ns: Int64Array, config: DoorbatchConfig) -> FloatArray | None:
    """Where the reference, at ``stamps_ns`` (the scans'), is the odometry moved rigidly, that motion T (x, y, yaw;
    r = T ⊕ o, taken at the first scan that has both: :func:`~doorbatch.pipeline.evaluate.trajectory_error.
    first_pose_correction`), else None. A copy is one within
    (:func:`~doorbatch.pipeline.evaluate.trajectory_error.rigid_copy_offset`) ``io.reference_repeats_odometry_m``
    plus the printed precision of the coordinates, 1e-5 of their magnitude, and ``_deg``, over at least
    ``io.reference_repeats_min_path_m`` of odometry path (None below: no telling). A CARMEN log's laser poses are
    its odometry unless the log was corrected, and a corrected log's odometry was replaced by the corrected poses,
    so the reader cannot tell the two apart; a robot may also republish its odometry as a pose topic. The poses are
    interpolated over any gap: a sparse reference repeats the odometry as a dense one does.
    """
    if reference is None or odometry is None:
        return None
    ref, ref_ok = interpolate_poses(reference.stamps_ns, reference.poses, stamps_ns)
    odo, odo_ok = interpolate_poses(odometry.stamps_ns, odometry.poses, stamps_ns)
    both = ref_ok & odo_ok & np.isfinite(ref).all(axis=1) & np.isfinite(odo).all(axis=1)  # a NaN pose says nothing
    ref, odo = ref[both], odo[both]
    io = config.io
    if ref.shape[0] < 2 or float(np.hypot(*np.diff(odo[:, :2], axis=0).T).sum()) < io.reference_repeats_min_path_m:
        return None  # too little motion for any odometry to have drifted from a true reference
    # printed precision: a CARMEN log writes 6 significant digits, a millimetre at 100 m
    tolerance_m = io.reference_repeats_odometry_m + 1e-5 * float(np.abs(np.concatenate([ref[:, :2], odo[:, :2]])).max())
    off_m, off_rad = rigid_copy_offset(odo, ref)
    if not (off_m <= tolerance_m and math.degrees(off_rad) <= io.reference_repeats_odometry_deg):
        return None  # NaN-safe: only offsets within the tolerances are a copy
    return first_pose_correction(odo, ref)


# No lidar measures below a millimetre; a 0.0 reading is a driver's "no data".
MIN_RANGE_M = 1e-3


def usable_range_limits(range_min: FloatArray, range_max: FloatArray) -> tuple[FloatArray, FloatArray, str | None]:
    """The scans' range limits with the ones that cannot be meant made harmless, and a warning saying so.

    range_min is at least 1 mm (a NaN or negative one too): a reading of exactly 0, some drivers' "no data", is
    then no hit at the laser's own position even where range_min is 0. A NaN range_max, or one at or below
    range_min (drivers that leave it 0), would make every reading a no-return (no hits, an empty map): it becomes
    +inf, no stated maximum (every finite reading a hit; the localizers then use
    ``localize.laser_max_range_fallback`` in their model)."""
    low = np.where(np.isfinite(range_min) & (range_min > MIN_RANGE_M), range_min, MIN_RANGE_M)
    bad = np.isnan(range_max) | (range_max <= low)
    if not bad.any():
        return low, range_max, None
    note = (f"{int(bad.sum())} of {bad.size} scans state a range_max that is NaN or not above range_min "
            f"(e.g. {float(range_max[bad][0])!r}): read as no stated maximum")
    return low, np.where(bad, np.inf, range_max), note


def with_no_return_code(ranges: Sequence[npt.ArrayLike], range_max: FloatArray,
                        config: DoorbatchConfig) -> tuple[FloatArray, str | None]:
    """``range_max`` with the scans that state none (+inf: :func:`usable_range_limits`) given their no-return code,
    where their readings show one, and a warning saying so.

    The code is the largest finite reading v of those scans when at least ``io.no_return_code_min_readings`` of
    their readings, and ``io.no_return_code_min_share`` of the finite ones, equal v exactly: a laser whose writer
    puts its maximum range in every beam without an echo (a simulator, a Foxglove log, which states no range
    limits). Those readings are then no returns (r ≥ range_max), not a ring of walls at the maximum range around
    every pose, and the sensor model takes v as the laser's reach. Scans with a stated range_max are left alone.
    """
    io = config.io
    unstated = np.flatnonzero(np.isposinf(range_max))
    if unstated.size == 0:
        return range_max, None
    # two passes over the scans as stored (float32), not a float64 copy of every reading of a long log
    scans = [np.asarray(ranges[i]) for i in unstated.tolist()]
    n_finite, code = 0, -math.inf
    for r in scans:
        finite = r[np.isfinite(r)]
        n_finite += finite.size
        code = max(code, float(finite.max())) if finite.size else code
    if n_finite == 0:
        return range_max, (f"{unstated.size} of {range_max.size} scans state no finite range_max (none, NaN or inf) "
                           "and have no finite reading")
    at_code = sum(int(np.count_nonzero(r == code)) for r in scans)
    if at_code < max(io.no_return_code_min_readings, io.no_return_code_min_share * n_finite):
        return range_max, (f"{unstated.size} of {range_max.size} scans state no finite range_max (none, NaN or inf) "
                           "and no finite reading repeats as a no-return code (their no-returns, if any, are inf or "
                           "NaN): every finite reading is a hit (the localizers take "
                           "localize.laser_max_range_fallback)")
    out = range_max.copy()
    out[unstated] = code
    return out, (f"{unstated.size} of {range_max.size} scans state no finite range_max, and {at_code} of their "
                 f"{n_finite} finite readings are exactly their largest, {code:g} m: read as the laser's no-return "
                 "code and range_max (io.no_return_code_min_readings, _share)")


def _aligned_colors(colors: BeamColors | None, beams: int) -> npt.NDArray[np.uint8]:
    """The scan's colors, or a zero array flagged by shape when the cloud is missing or misaligned."""
    if colors is None or colors.rgb.shape[0] != beams:
        return np.zeros((0, 3), dtype=np.uint8)
    return colors.rgb
