"""Run ``doorbatch map`` end to end: build the map, write the map directory and its manifest."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.errors import UsageError
from doorbatch.io.manifest import Manifest
from doorbatch.io.mapdir import write_map_dir
from doorbatch.pipeline.mapping import DoorMap, build_map, preview_doors

STAGES = ("grid",)  # the em stage arrives with paper 001's object maps


@dataclass(frozen=True)
class MapRunSummary:
    """What ``doorbatch map`` wrote."""

    map_dir: str
    pose_source: str
    doors: int
    passes: int
    files: list[str]
    warnings: list[str]


def run_map(logs: Sequence[Path], out: Path, config: DoorbatchConfig, stages: Sequence[str] = ("grid",),
            progress: Callable[[int], object] | None = None) -> tuple[DoorMap, MapRunSummary]:
    """Build the door map of ``logs`` (one pass each) and write ``out``/{map.yaml, map.pgm, doors.parquet,
    preview.png, manifest.json}.

    Raises:
        UsageError: an unknown stage.
        PipelineError, InputDataError: as :func:`build_map`.
    """
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        raise UsageError(f"--stages {','.join(unknown)} is not available (stages: {', '.join(STAGES)})")
    manifest = Manifest.start(config.as_dict(), [Path(p) for p in logs], command="map", stages=list(stages))
    door_map = build_map(logs, config, progress)
    files = write_map_dir(out, door_map.static_map, preview_doors(door_map.doors),
                          [d.n_observations for d in door_map.doors], "grid",
                          [p.poses[p.valid] for p in door_map.passes])
    manifest.extra["pose_source"] = door_map.pose_source
    for w in door_map.warnings:
        manifest.warn(w)
    manifest.stage_seconds.update(door_map.stage_seconds)
    manifest.finish()
    manifest.write(out / "manifest.json")
    summary = MapRunSummary(str(out), door_map.pose_source, len(door_map.doors), len(door_map.passes),
                            [str(f) for f in [*files, out / "manifest.json"]], door_map.warnings)
    return door_map, summary
