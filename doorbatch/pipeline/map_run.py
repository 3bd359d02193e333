"""Run ``doorbatch map`` end to end: build the map, write the map directory and its manifest."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import InputDataError, UsageError
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.annotated_mcap import write_annotated_mcap
from doorbatch.io.manifest import Manifest
from doorbatch.io.mapdir import MappedPass, door_set_of_previews, mapping_annotations, write_map_dir
from doorbatch.io.object_map import read_classes, write_classes, write_walls
from doorbatch.io.recording import Recording
from doorbatch.io.staged_dir import staged_files
from doorbatch.pipeline.door_rows import DoorRow, em_rows, grid_rows, with_grid_doors
from doorbatch.pipeline.mapping import DoorMap, build_map, mapping_passes, without_leaves
from doorbatch.pipeline.objectmap.stage import ObjectMapResult, em_stage

STAGES = ("grid", "em")  # em (paper 001) takes the grid stage's poses: grid always runs


def default_stages(recordings: Sequence[Recording]) -> list[str]:
    """grid,em when every log has per-beam colours, else grid (DESIGN: em is the default with colour)."""
    return ["grid", "em"] if recordings and all(r.colors is not None for r in recordings) else ["grid"]


@dataclass(frozen=True)
class MapRunSummary:
    """What ``doorbatch map`` wrote."""

    map_dir: str
    pose_source: str
    doors: int
    passes: int
    files: list[str]
    warnings: list[str]


def _mapped_passes(recordings: Sequence[Recording], door_map: DoorMap, door_angles: npt.NDArray[np.float64]
                   ) -> list[MappedPass]:
    """Each pass's scans that have a pose, with the odometry at their stamps (when the log has odometry)."""
    out = []
    for t, (rec, p) in enumerate(zip(recordings, door_map.passes, strict=True)):
        stamps, poses = p.stamps_ns[p.valid], p.poses[p.valid]
        odom = None
        # the log's tree (bridging and joining move rec.odometry only), else the odometry used, where it covers all
        for series in (rec.drawn_odometry, rec.odometry):
            if series is None:
                continue
            at, ok = interpolate_poses(series.stamps_ns, series.poses, stamps)
            if ok.all():
                odom = at
                break
        out.append(MappedPass(stamps, poses, odom, door_angles[t], rec.log_clock))
    return out


def _write_mapping_mcap(logs: Sequence[Path], recordings: Sequence[Recording], door_map: DoorMap,
                        rows: Sequence[DoorRow], path: Path, config: DoorbatchConfig) -> Path:
    """annotated.mcap of the mapping run (:func:`~doorbatch.io.mapdir.mapping_annotations`); each door at its
    angle in each pass where its stage saw the leaf."""
    angles = np.stack([r.pass_angles for r in rows], axis=1) if rows else np.full((len(recordings), 0), np.nan)
    write_annotated_mcap([Path(p) for p in logs], path,
                         mapping_annotations(_mapped_passes(recordings, door_map, angles), door_map.static_map,
                                             door_set_of_previews([r.door for r in rows]), config.frames.map,
                                             config.frames.odom),
                         config)
    return path


# What a map directory holds only with some options (the em stage; --mcap).
OPTIONAL_MAP_FILES = ("walls.parquet", "classes.json", "annotated.mcap")


def _optional_files_written(out: Path) -> list[str]:
    """The optional files the last ``doorbatch map`` into ``out`` wrote (its manifest's ``optional_files``)."""
    try:
        return list(Manifest.read(out / "manifest.json").extra.get("optional_files", []))
    except (OSError, InputDataError, ValueError):
        return []


def _remove_stale_map_files(out: Path, earlier: Sequence[str], written: Sequence[Path], logs: Sequence[Path]) -> None:
    """The optional files an earlier map into ``out`` wrote (``earlier``: :func:`_optional_files_written`, read
    before this run's files came in) that this run did not: they would pass for this map's. Never a file the user
    put there, never an input."""
    inputs = {Path(p).resolve() for p in logs}
    for name in OPTIONAL_MAP_FILES:
        path = out / name
        if name in earlier and path not in written and path.resolve() not in inputs:
            path.unlink(missing_ok=True)


def run_map(logs: Sequence[Path], out: Path, config: DoorbatchConfig, stages: Sequence[str] | None = ("grid",),
            progress: Callable[[int], object] | None = None, classes_file: Path | None = None,
            mcap: bool = False) -> tuple[DoorMap, MapRunSummary]:
    """Build the door map of ``logs`` (one pass each) and write ``out``/{map.yaml, map.pgm, doors.parquet,
    preview.png, manifest.json}; with the em stage also walls.parquet and classes.json, and doors.parquet
    holds the em doors (source ``em``) and, with ``em.keep_grid_doors``, the grid doors in doorways the em
    stage left without a door it saw move (source ``grid``; :func:`~doorbatch.pipeline.door_rows.with_grid_doors`).
    ``stages`` None: :func:`default_stages`. ``classes_file``: class
    parameters applied without relearning (paper 001 Fig. 5b). ``mcap``: also ``out``/annotated.mcap, every
    message of the passes with the map, the doors per pass, the poses, paths and map→odom (DESIGN's annotated
    MCAP, :func:`~doorbatch.io.mapdir.mapping_annotations`).

    Raises:
        UsageError: an unknown stage, or --classes without the em stage.
        PipelineError, InputDataError: as :func:`build_map`; a bad classes file.
    """
    unknown = [s for s in (stages or ()) if s not in STAGES]
    if unknown:
        raise UsageError(f"--stages {','.join(unknown)} is not available (stages: {', '.join(STAGES)})")
    if mcap and (out / "annotated.mcap").resolve() in {Path(p).resolve() for p in logs}:
        raise UsageError(f"--mcap would write {out / 'annotated.mcap'}, which is one of the logs: choose another -o")
    classes = read_classes(classes_file) if classes_file is not None else None
    t0 = time.perf_counter()
    logs, recordings, ordered = mapping_passes(logs, config, with_colors=stages is None or "em" in stages)
    read_s = time.perf_counter() - t0
    stages = default_stages(recordings) if stages is None else list(stages)
    if classes is not None and "em" not in stages:
        raise UsageError("--classes applies to the em stage: add it with --stages grid,em")
    manifest = Manifest.start(config.as_dict(), logs, command="map", stages=list(stages))
    door_map = build_map(logs, config, progress, recordings)
    door_map.stage_seconds["read"] = read_s  # build_map read nothing: the logs were read above, with colours
    if ordered:
        door_map = replace(door_map, warnings=[ordered, *door_map.warnings])
    rows = grid_rows(door_map.doors, len(door_map.passes))
    em: ObjectMapResult | None = None
    if "em" in stages and recordings is not None:
        t0 = time.perf_counter()
        em = em_stage(recordings, door_map.passes, config, classes, door_map.doors)
        rows = (with_grid_doors(em_rows(em.doors), rows, config.em.existing_door_radius_m)
                if config.em.keep_grid_doors else em_rows(em.doors))
        door_map = without_leaves(door_map, [r.door for r in rows], config)
        door_map.stage_seconds["em"] = time.perf_counter() - t0
    trajectories = [p.poses[p.valid] for p in door_map.passes]
    walls = [w.endpoints() for w in em.object_map.walls if w.segments.size] if em is not None else []
    earlier = _optional_files_written(out)
    with staged_files(out) as stage:  # an interrupted write leaves ``out`` as it was
        files = write_map_dir(stage, door_map.static_map, [r.door for r in rows], [r.n_observations for r in rows],
                              [r.source for r in rows], trajectories, walls=np.concatenate(walls) if walls else None)
        if em is not None:
            write_walls(stage / "walls.parquet", em.object_map.walls)
            write_classes(stage / "classes.json", em.object_map.classes)
            files += [stage / "walls.parquet", stage / "classes.json"]
            manifest.extra["em"] = {"beams": em.n_beams, "log_posterior": em.log_posterior,
                                    "walls": len(em.object_map.walls), "doors": len(em.doors),
                                    "grid_doors": len(door_map.doors),
                                    "grid_doors_kept": sum(r.source == "grid" for r in rows),
                                    "classes_given": classes is not None,
                                    "scan_stride": em.strides[0], "beam_stride": em.strides[1],
                                    "final_beams": em.final_beams, "final_scan_thinning": em.final_scan_thinning,
                                    "final_scan_stride": em.final_strides[0], "final_beam_stride": em.final_strides[1]}
            if classes is not None and classes.has_color and not em.object_map.classes.has_color:
                why = "em.use_color is off" if not config.em.use_color else "the logs have no beam colours"
                manifest.warn(f"em: {classes_file} has colour classes, but {why}: its widths only were applied")
            if em.final_scan_thinning > 1:
                manifest.warn(f"em: the final wall step kept 1 scan in {em.final_scan_thinning} ({em.final_beams} "
                              f"beams; em.final_max_beams {config.em.final_max_beams})")
        if mcap and recordings is not None:
            files.append(_write_mapping_mcap(logs, recordings, door_map, rows, stage / "annotated.mcap", config))
        files = [out / f.name for f in files]
        manifest.extra["optional_files"] = [f.name for f in files if f.name in OPTIONAL_MAP_FILES]
        manifest.extra["pose_source"] = door_map.pose_source
        for w in door_map.warnings:
            manifest.warn(w)
        manifest.stage_seconds.update(door_map.stage_seconds)
        manifest.finish()
        manifest.write(stage / "manifest.json")
    _remove_stale_map_files(out, earlier, files, logs)  # once this map's files are all in
    summary = MapRunSummary(str(out), door_map.pose_source, len(rows), len(door_map.passes),
                            [str(f) for f in [*files, out / "manifest.json"]], door_map.warnings)
    return door_map, summary
