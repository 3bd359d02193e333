"""``doorbatch doorpose``: door poses over a log (paper 003, Sec. III-B), optionally matched to a map.

The stage in outline::

    inputs   = TF, camera_info, scans, robot poses, and door boxes (topic, or the user's model per image)
    for each image's boxes:  the scan nearest in time (within io.stamp_tolerance_s), its points moved to where
                             the robot was at the image's stamp (odometry, else the reference: scan_at_image)
                             → door in the camera plane (fusion) → base_link → output frame (robot pose)
                             → the mapped door it belongs to (with --map) and that door's current angle
    outputs  = door_poses.parquet, annotated.mcap, manifest.json
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import TransformError
from doorbatch.geometry.camera import camera_from_info, level_rotation, scan_in_camera
from doorbatch.geometry.rotations import invert_transform
from doorbatch.geometry.se2 import interpolate_poses, relative, rotation_matrix
from doorbatch.io.doorpose_inputs import DoorPoseInputs
from doorbatch.io.recording import PoseSeries
from doorbatch.maps import DoorSet
from doorbatch.pipeline.doorpose.association import associate
from doorbatch.pipeline.doorpose.fusion import estimate_door, to_planar
from doorbatch.pipeline.doorpose.line_fit import LineFit
from doorbatch.records import Detection, class_name

log = logging.getLogger(__name__)
FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DoorPoseEstimate:
    """One door pose (output frame) with what it came from, for the table and the annotations."""

    stamp_ns: int  # the image's stamp
    scan_stamp_ns: int
    door_id: int
    door_angle: float  # the matched door's current angle (rad, CCW +), NaN if unmatched
    center: FloatArray  # (2,)
    yaw: float
    width_m: float
    handle_side: str
    goal: FloatArray  # (3,)
    left: FloatArray  # (2,) door edges
    right: FloatArray  # (2,)
    box: Detection
    camera_frame: str


@dataclass(frozen=True)
class DoorPoses:
    """All door poses of a log (DESIGN: pipeline/doorpose → DoorPoses)."""

    log: str
    fit: str
    frame: str
    estimates: list[DoorPoseEstimate]
    images: int  # images (box sets) considered
    paired: int  # of those with a scan within the stamp tolerance
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return len(self.estimates)


def output_frame(inputs: DoorPoseInputs, config: DoorbatchConfig) -> tuple[str, PoseSeries | None]:
    """The frame door poses are given in, and the robot poses that put them there (None: base_link)."""
    want = config.doorpose.frame
    if want == "auto":
        want = "map" if inputs.reference is not None else "odom" if inputs.odometry is not None else "base_link"
    if want == "base_link":
        return inputs.base_link, None
    series = inputs.reference if want == "map" else inputs.odometry
    if series is None:
        raise TransformError(f"doorpose.frame={want} needs {'a reference pose' if want == 'map' else 'odometry'} "
                             "in the log", path=inputs.path)
    return series.frame_id or want, series


@dataclass(frozen=True)
class FrameLink:
    """Where the output frame (a reference's map) meets the odometry's tree: both robot poses at stamps, so that
    the annotations can give map→odom and a viewer can draw the door poses over the robot and its scans."""

    odom_frame: str
    stamps_ns: npt.NDArray[np.int64]
    pose: npt.NDArray[np.float64]  # (K, 3) in the output frame
    odom: npt.NDArray[np.float64]  # (K, 3) in the odometry frame


def frame_link(inputs: DoorPoseInputs, config: DoorbatchConfig, stamps_ns: npt.ArrayLike) -> FrameLink | None:
    """The output frame's link to the odometry's at ``stamps_ns`` (where both poses interpolate), or None where
    the poses are in the odometry frame or base_link already, or the log has no odometry."""
    frame, series = output_frame(inputs, config)
    odometry = inputs.odometry
    if series is None or odometry is None or series is odometry or odometry.frame_id in ("", frame):
        return None
    stamps = np.asarray(stamps_ns, dtype=np.int64)
    pose, ok = interpolate_poses(series.stamps_ns, series.poses, stamps)
    odom, ok_odom = interpolate_poses(odometry.stamps_ns, odometry.poses, stamps)
    keep = ok & ok_odom
    return FrameLink(odometry.frame_id, stamps[keep], pose[keep], odom[keep])


def nearest_scan(scan_stamps_ns: npt.NDArray[np.int64], stamp_ns: int, tolerance_ns: int) -> int | None:
    """Index of the scan nearest in time to ``stamp_ns``, if within the tolerance."""
    if scan_stamps_ns.size == 0:
        return None
    i = int(np.searchsorted(scan_stamps_ns, stamp_ns))
    cands = [j for j in (i - 1, i) if 0 <= j < scan_stamps_ns.size]
    best = min(cands, key=lambda j: abs(int(scan_stamps_ns[j]) - stamp_ns))
    return best if abs(int(scan_stamps_ns[best]) - stamp_ns) <= tolerance_ns else None


def scan_at_image(points_cam: FloatArray, cam_to_base: FloatArray, motion: PoseSeries | None, scan_ns: int,
                  image_ns: int) -> tuple[FloatArray, int]:
    """The scan's points (N, 3) in the camera frame, moved from the robot's pose at the scan's stamp to its pose at
    the image's (the planar motion Δ = o(image)⁻¹ ⊕ o(scan) of ``motion``, in base_link: p ↦ C⁻¹ Δ C p with C
    camera → base_link), and the stamp they now hold. Unmoved, at the scan's stamp, where ``motion`` does not
    cover both stamps. A camera and a laser are never triggered together: a scan 25 ms off the image during a
    0.8 rad/s turn puts the door 0.1 m off (measured by a user's simulator)."""
    if motion is None or scan_ns == image_ns:
        return points_cam, scan_ns
    at, ok = interpolate_poses(motion.stamps_ns, motion.poses, [image_ns, scan_ns])
    if not ok.all():
        return points_cam, scan_ns
    dx, dy, dyaw = relative(at[0], at[1])
    delta = np.eye(4)
    delta[:2, :2], delta[:2, 3] = rotation_matrix(dyaw), (dx, dy)
    mat = invert_transform(cam_to_base) @ delta @ cam_to_base
    return points_cam @ mat[:3, :3].T + mat[:3, 3], image_ns


def camera_tilt_deg(inputs: DoorPoseInputs, base_link: str, camera_frame: str) -> float | None:
    """Elevation of the camera's optical axis (its frame's z) above base_link's horizontal plane, at the first
    detection; None without boxes or a transform."""
    if not inputs.detections:
        return None
    try:
        mat = inputs.tf.lookup(base_link, camera_frame, inputs.detections[0].stamp_ns, hold_constant=True)
    except TransformError:
        return None
    return math.degrees(math.asin(max(-1.0, min(1.0, float(mat[2, 2])))))


def estimate_door_poses(inputs: DoorPoseInputs, config: DoorbatchConfig, doors: DoorSet | None = None,
                        fit: LineFit | None = None, progress: Callable[[int], object] | None = None) -> DoorPoses:
    """Door poses of every image with a usable door box (module docstring)."""
    dc = config.doorpose
    method = fit or LineFit(dc.fit)
    camera = camera_from_info(inputs.camera_info)
    frame, series = output_frame(inputs, config)
    rng = np.random.default_rng(config.seed if dc.seed is None else dc.seed)
    scan_stamps = np.array([s.stamp_ns for s in inputs.scans], dtype=np.int64)
    tol = int(config.io.stamp_tolerance_s * 1e9)
    warnings: list[str] = []
    out: list[DoorPoseEstimate] = []
    paired = 0
    open_leaves = 0  # estimates whose line turns from the wall beside it: an open door's leaf
    classes: set[str] = set()  # the box classes seen, as resolved (for the warning when none is a door)
    door_class = class_name(dc.door_class, dc.class_names)
    door_scores: list[float] = []
    for boxes in inputs.detections:
        if progress is not None:
            progress(1)
        named = [(class_name(d.class_id, dc.class_names), d.score) for d in boxes.detections]
        classes.update(name for name, _ in named)
        door_scores += [score for name, score in named if name == door_class]
        i = nearest_scan(scan_stamps, boxes.stamp_ns, tol)
        if i is None:
            continue
        paired += 1
        if not boxes.detections:
            continue
        scan = inputs.scans[i]
        try:
            points, _ = scan_in_camera(scan, inputs.tf, camera.frame_id)
            cam_to_base = inputs.tf.lookup(inputs.base_link, camera.frame_id, boxes.stamp_ns, hold_constant=True)
        except TransformError as err:
            warnings.append(f"image at {boxes.stamp_ns / 1e9:.3f} s skipped: {err.reason}")
            continue
        points, seen_ns = scan_at_image(points, cam_to_base, inputs.odometry or inputs.reference, scan.stamp_ns,
                                        boxes.stamp_ns)
        try:
            level = level_rotation(cam_to_base)
        except ValueError:
            warnings.append(f"image at {boxes.stamp_ns / 1e9:.3f} s skipped: the camera looks straight up or down")
            continue
        door = estimate_door(camera, boxes.detections, points, dc, rng, method, level)
        if door is None:
            continue
        pose = None
        if series is not None:
            poses, valid = interpolate_poses(series.stamps_ns, series.poses, [seen_ns])
            if not valid[0]:
                continue
            pose = poses[0]
        planar = to_planar(door, cam_to_base, pose, level)
        match = associate(planar.left, planar.right, doors, dc.association_max_distance_m) if doors else None
        open_leaves += bool(door.wall_turn_deg > dc.open_leaf_warn_deg)
        out.append(DoorPoseEstimate(boxes.stamp_ns, scan.stamp_ns, -1 if match is None else match.door_id,
                                    float("nan") if match is None else match.angle, planar.center, planar.yaw,
                                    planar.width_m, door.handle_side.value, planar.goal, planar.left, planar.right,
                                    door.box, camera.frame_id))
    if len(warnings) > 3:
        warnings = [*warnings[:3], f"... and {len(warnings) - 3} more images skipped for missing transforms"]
    if open_leaves:
        warnings.append(f"{open_leaves} of {len(out)} door poses lie on a line turned over {dc.open_leaf_warn_deg:g} "
                        "deg from the wall beside the door: a door standing open, whose pose is its leaf's, not the "
                        "doorway's (doorpose.open_leaf_warn_deg)")
    tilt = camera_tilt_deg(inputs, inputs.base_link, camera.frame_id)
    if tilt is not None and abs(tilt) > dc.max_camera_tilt_deg:
        warnings.append(f"the camera's optical axis (z of frame {camera.frame_id!r}) points {abs(tilt):.1f} deg "
                        f"{'above' if tilt > 0 else 'below'} the horizontal: is {camera.frame_id!r} the optical "
                        "frame (z forward)? A camera_link (x forward) in its place turns every ray")
    if door_scores and max(door_scores) < dc.confidence_threshold:
        warnings.append(f"all {len(door_scores)} boxes of class {door_class!r} score below "
                        f"doorpose.confidence_threshold {dc.confidence_threshold} (best {max(door_scores):.3f})")
    if classes and door_class not in classes:
        warnings.append(f"no box of class {door_class!r} in {len(inputs.detections)} detection messages; classes "
                        f"seen: {', '.join(sorted(classes))} (doorpose.door_class, doorpose.class_names)")
    if inputs.detections and not any(boxes.detections for boxes in inputs.detections):
        warnings.append(f"none of {len(inputs.detections)} detection messages holds a box")
    if doors and (series is None or series is not inputs.reference):
        warnings.append(f"door poses in {frame!r}, not in a reference's frame: they are matched to --map's doors as "
                        "if the map were built in it (map and log from one odometry frame); else the matches and "
                        "angles are wrong")
    if inputs.detections and paired == 0:
        warnings.append(f"none of {len(inputs.detections)} detection messages has a scan within "
                        f"{config.io.stamp_tolerance_s} s of its stamp (io.stamp_tolerance_s; unset stamps?)")
    return DoorPoses(Path(inputs.path).name, method.value, frame, out, len(inputs.detections), paired,
                     [*inputs.warnings, *warnings])


@dataclass(frozen=True)
class DoorPoseRunSummary:
    """What ``doorbatch doorpose`` wrote."""

    run_dir: str
    fit: str
    frame: str
    images: int
    paired: int
    door_poses: int
    matched: int
    door_angles: dict[int, float]  # matched door → median current angle (rad)
    files: list[str]


def run_doorpose(log_path: Path, out: Path, config: DoorbatchConfig, map_path: Path | None = None,
                 detector: str | None = None, fit: str | None = None,
                 progress: Callable[[int], object] | None = None) -> tuple[DoorPoses, DoorPoseRunSummary]:
    """Estimate door poses over a log and write the run directory: door_poses.parquet, annotated.mcap,
    manifest.json."""
    from doorbatch.io.annotated_mcap import on_log_clock, write_annotated_mcap
    from doorbatch.io.detector_model import load_detector
    from doorbatch.io.doorpose_inputs import read_doorpose_inputs
    from doorbatch.io.doorpose_rundir import doorpose_annotations, write_door_poses
    from doorbatch.io.manifest import Manifest, StageTimer
    from doorbatch.io.mapdir import read_door_set
    from doorbatch.io.staged_dir import staged_files
    from doorbatch.pipeline.doorpose.yolo import detect_image

    dc = config.doorpose.model_copy(update={k: v for k, v in (("detector", detector), ("fit", fit)) if v})
    config = config.model_copy(update={"doorpose": dc})
    inputs_list = [log_path]
    model = None
    if dc.detector != "topic":
        inputs_list.append(Path(dc.detector))
        model = load_detector(Path(dc.detector), dc.torch_device)
    if map_path is not None:
        inputs_list.append(map_path / "doors.parquet" if map_path.is_dir() else map_path)
    manifest = Manifest.start(config.as_dict(), inputs_list, command="doorpose", fit=dc.fit, detector=dc.detector)
    forward = model.forward if model is not None else None
    timer = StageTimer()
    with timer("read"):  # the detector runs on each image as it is read
        inputs = read_doorpose_inputs(log_path, config, None if forward is None else
                                      (lambda image: detect_image(forward, image.pixels, dc)))
    doors = read_door_set(map_path) if map_path is not None else None
    with timer("doorpose"):
        result = estimate_door_poses(inputs, config, doors, LineFit(dc.fit), progress)
    with staged_files(out) as stage:  # an interrupted write leaves ``out`` as it was
        with timer("write"):
            write_door_poses(stage / "door_poses.parquet", result)
            link = frame_link(inputs, config, [e.stamp_ns for e in result.estimates])
            write_annotated_mcap(log_path, stage / "annotated.mcap",  # sim-time stamps: beside the input's messages
                                 on_log_clock(doorpose_annotations(result, link), inputs.log_clock), config,
                                 replaced_tf=[] if link is None else [(result.frame, link.odom_frame)])
        for w in result.warnings:
            manifest.warn(w)
        matched = [e for e in result.estimates if e.door_id >= 0]
        angles = {k: float(np.median([e.door_angle for e in matched if e.door_id == k]))
                  for k in sorted({e.door_id for e in matched})}
        manifest.extra.update({"door_poses": len(result), "matched": len(matched), "door_angles": angles})
        manifest.finish(timer)
        manifest.write(stage / "manifest.json")
    files = [str(out / f) for f in ("door_poses.parquet", "annotated.mcap", "manifest.json")]
    summary = DoorPoseRunSummary(str(out), result.fit, result.frame, result.images, result.paired, len(result),
                                 len(matched), angles, files)
    log.debug("doorpose summary: %s", asdict(summary))
    return result, summary


@dataclass(frozen=True)
class ApproachRunSummary:
    """What ``doorbatch doorpose --simulate-approach`` wrote: per method the mean summed error."""

    run_dir: str
    experiment: str
    samples: int
    mean_error: dict[str, float]
    files: list[str]


def run_simulated_experiment(experiment_path: Path, out: Path, config: DoorbatchConfig
                             ) -> ApproachRunSummary:
    """Run a door pose experiment file (Table I or II on simulated scenes) and write metrics.parquet and
    manifest.json into ``out``."""
    from doorbatch.io.manifest import Manifest
    from doorbatch.io.parquet import write_table
    from doorbatch.pipeline.doorpose.experiment import experiment_metrics, load_experiment
    from doorbatch.pipeline.evaluate.report import metric_columns

    exp, config = load_experiment(experiment_path, config)
    manifest = Manifest.start(config.as_dict(), [experiment_path], command="doorpose --simulate-approach",
                              experiment=exp.experiment)
    rows, result = experiment_metrics(exp, config, experiment_path.stem)
    out.mkdir(parents=True, exist_ok=True)
    write_table("metrics", metric_columns(rows), out / "metrics.parquet")
    means = {k: float(np.mean(v[np.isfinite(v)])) for k, v in result.errors.items()}
    manifest.extra.update({"mean_error": means})
    manifest.finish()
    manifest.write(out / "manifest.json")
    return ApproachRunSummary(str(out), exp.experiment, exp.samples, means,
                              [str(out / "metrics.parquet"), str(out / "manifest.json")])
