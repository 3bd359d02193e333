"""Experiments: sweeps of localization runs (logs × methods × particle counts × seeds, one init mode), run in
parallel and evaluated into one report (``doorbatch evaluate --experiment FILE -o DIR``).

An experiment file (``configs/experiments/*.yaml``; relative paths are relative to the file)::

    name: tracking
    title: Tracking error along the corridor (paper 000 Figs. 5-7)
    map: [../../datasets/sample/logs/map_pass1.mcap, ...]   # logs to build the map from, or a map directory
    logs: [../../datasets/sample/logs/loc_closed.mcap, ...]  # or a map_server YAML
    methods: [mcl, rbpf]
    particles: [5000]          # localize.max_particles = global_particles = N (null: the config's)
    seeds: [0, 1, 2]           # the filter's seed (config seed)
    init: reference            # reference | global | X,Y,YAW
    set: ["localize.z_rand=0.2"]   # config overrides for every run

Output: ``DIR/map/`` (when built), ``DIR/runs/<log stem>/<method>[_n<N>]_s<seed>/`` (trajectory.parquet,
door_states.parquet, trajectory.tum, manifest.json with the sweep point in ``extra.params``; no annotated
MCAP, which the metrics do not need), and the report (metrics.parquet with ``params`` = the sweep point,
report.md, report.html, plots). Each run is deterministic given its seed, so the workers' order does not
matter.
"""

from __future__ import annotations

import itertools
import logging
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field

from doorbatch.config import DoorbatchConfig, load_config, parse_init
from doorbatch.io.manifest import Manifest, StageTimer
from doorbatch.io.sim_truth import output_paths
from doorbatch.pipeline.evaluate.report import Evaluation

log = logging.getLogger(__name__)


class ExperimentSpec(BaseModel):
    """An experiment file, validated (unknown keys are errors)."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    title: str = ""
    # Logs to build the map from, a map directory / map_server YAML, or "truth": each log's simulator truth
    # (static map and every door, moved or not; doorbatch.pipeline.localize.run.truth_localization_map).
    map: Literal["truth"] | tuple[Path, ...] | Path
    logs: tuple[Path, ...] = Field(min_length=1)
    methods: tuple[Literal["mcl", "rbpf"], ...] = Field(("mcl", "rbpf"), min_length=1)
    particles: tuple[int | None, ...] = Field((None,), min_length=1)
    seeds: tuple[int, ...] = Field((0,), min_length=1)
    init: str = "reference"
    set: tuple[str, ...] = ()

    def resolved(self, base: Path) -> ExperimentSpec:
        """The spec with relative paths made relative to ``base`` (the experiment file's folder)."""

        def fix(p: Path) -> Path:
            return p if p.is_absolute() else base / p

        map_paths: Literal["truth"] | tuple[Path, ...] | Path
        if self.map == "truth":
            map_paths = "truth"
        else:
            map_paths = tuple(fix(p) for p in self.map) if isinstance(self.map, tuple) else fix(Path(self.map))
        return self.model_copy(update={"map": map_paths, "logs": tuple(fix(p) for p in self.logs)})


class SweepPoint(BaseModel):
    """One localization run of an experiment."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    log: Path
    method: Literal["mcl", "rbpf"]
    particles: int | None
    seed: int
    init: str

    @property
    def run_name(self) -> str:
        """``<method>_n<particles>_s<seed>`` (``<method>_s<seed>`` with the config's particle count)."""
        n = "" if self.particles is None else f"_n{self.particles}"
        return f"{self.method}{n}_s{self.seed}"

    def params(self) -> dict[str, Any]:
        """The params column of metrics.parquet."""
        return {"particles": self.particles, "seed": self.seed, "init": self.init}


def sweep_points(spec: ExperimentSpec) -> list[SweepPoint]:
    """logs × methods × particles × seeds, in that order."""
    return [SweepPoint(log=lg, method=m, particles=n, seed=s, init=spec.init)
            for lg, m, n, s in itertools.product(spec.logs, spec.methods, spec.particles, spec.seeds)]


def point_config(config: DoorbatchConfig, point: SweepPoint) -> DoorbatchConfig:
    """The config of one run: the seed and the particle count (``localize.max_particles`` =
    ``global_particles`` = N, ``min_particles`` at most N, as ``doorbatch localize --particles``)."""
    lc = config.localize
    if point.particles is not None:
        lc = lc.model_copy(update={"max_particles": point.particles, "global_particles": point.particles,
                                   "min_particles": min(lc.min_particles, point.particles)})
    return config.model_copy(update={"seed": point.seed, "localize": lc.model_copy(update={"seed": None})})


def run_point(point: SweepPoint, map_path: Path | None, run_dir: Path, config: DoorbatchConfig) -> Path:
    """Localize one sweep point and write its run directory (no annotated MCAP). Runs in a worker process.
    ``map_path`` None: the log's simulator truth map (``<log stem>.truth.yaml`` beside it)."""
    from doorbatch.io.rundir import write_run_tables
    from doorbatch.pipeline.localize.run import (
        load_localization_map,
        localize,
        map_input_files,
        truth_localization_map,
    )

    truth = output_paths(point.log)["truth"]
    if map_path is None:
        inputs = [point.log, truth]
        lmap = truth_localization_map(truth, config.localize)
    else:
        inputs = [point.log, *map_input_files(map_path)]
        lmap = load_localization_map(map_path, config.localize)
    manifest = Manifest.start(config.as_dict(), inputs, command="evaluate --experiment", method=point.method,
                              init=point.init, params=point.params())
    timer = StageTimer()
    with timer("localize"):
        result = localize(point.log, lmap, config, point.method, parse_init(point.init))
    with timer("write"):
        write_run_tables(run_dir, result)
    manifest.extra.update(result.manifest_extra())
    for w in result.warnings:
        manifest.warn(w)
    manifest.finish(timer)
    manifest.write(run_dir / "manifest.json")
    return run_dir


def _build_map(spec: ExperimentSpec, out: Path, config: DoorbatchConfig) -> Path | None:
    if spec.map == "truth":
        return None
    if not isinstance(spec.map, tuple):
        return Path(spec.map)
    from doorbatch.pipeline.map_run import run_map

    map_dir = out / "map"
    run_map(spec.map, map_dir, config)
    return map_dir


def run_experiment(spec: ExperimentSpec, out: Path, config: DoorbatchConfig, *, workers: int = 1) -> Evaluation:
    """Build the map (if the spec lists logs), run every sweep point (``workers`` processes), evaluate all runs
    and the map, and write the report into ``out``.

    Raises:
        ConfigError: a bad override in ``set``.
        InputDataError, PipelineError: as the map, localize and evaluate stages.
    """
    from doorbatch.pipeline.evaluate.stage import evaluate_run_dirs
    from doorbatch.progress import progress_bar

    base = load_config(extra=config.as_dict(), overrides=spec.set)
    map_path = _build_map(spec, out, base)
    points = sweep_points(spec)
    jobs = [(p, map_path, out / "runs" / p.log.name.split(".")[0] / p.run_name, point_config(base, p))
            for p in points]
    with progress_bar(len(jobs), f"experiment {spec.name}", unit="run") as bar:
        if workers <= 1:
            for job in jobs:
                run_point(*job)
                bar.update(1)
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                for _ in pool.map(run_point, *zip(*jobs, strict=True)):
                    bar.update(1)
    dirs = [job[2] for job in jobs] + ([map_path] if map_path is not None and map_path.is_dir() else [])
    return evaluate_run_dirs(dirs, out, base, title=spec.title or spec.name)


def run_experiment_file(path: Path, out: Path, config: DoorbatchConfig, *, workers: int = 1) -> Evaluation:
    """:func:`run_experiment` of an experiment file (paths relative to the file).

    Raises:
        ConfigError: the file is not a valid experiment.
    """
    from doorbatch.io.experiment_file import experiment_kind, read_experiment

    if experiment_kind(path) == "doorpose":
        return run_doorpose_experiment(path, out, config)
    return run_experiment(read_experiment(path), out, config, workers=workers)


def run_doorpose_experiment(path: Path, out: Path, config: DoorbatchConfig) -> Evaluation:
    """A door pose experiment file (paper 003 Table I or II on simulated scenes) evaluated into the same
    report as the localization experiments (its metrics rows; no trajectory plots).

    Raises:
        ConfigError: the file is not a valid door pose experiment.
    """
    from doorbatch.io.report_writer import write_report
    from doorbatch.pipeline.doorpose.experiment import experiment_metrics, load_experiment

    exp, exp_config = load_experiment(path, config)
    rows, _ = experiment_metrics(exp, exp_config, path.stem)
    evaluation = Evaluation(rows, [], [], [], [], title=exp.description or exp.experiment)
    write_report(evaluation, out)
    return evaluation
