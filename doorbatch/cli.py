"""The ``doorbatch`` command line: thin click commands, one library call each.

Errors: a :class:`~doorbatch.errors.DoorbatchError` becomes one ``error:`` line on stderr and its exit
code (DESIGN.md: 2 usage/config, 3 bad input, 4 partial batch); any other exception is a bug: one line
on stderr and the traceback in the log file.
"""

from __future__ import annotations

import functools
import json
import logging
import sys
import tempfile
import traceback
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any, TypeVar

import click

from doorbatch import __version__
from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.errors import DoorbatchError, ExitCode, LogContentError, UsageError
from doorbatch.interrupts import sigterm_as_interrupt
from doorbatch.progress import set_progress_enabled

log = logging.getLogger("doorbatch")
F = TypeVar("F", bound=Callable[..., Any])
CRASH_LOG = Path(tempfile.gettempdir()) / "doorbatch-crash.log"


class Context:
    """What every command gets from the common options."""

    def __init__(self, config: DoorbatchConfig, as_json: bool, quiet: bool, config_file: Path | None = None,
                 overrides: tuple[str, ...] = (), launch_args: dict[str, str] | None = None) -> None:
        self.config = config
        self.as_json = as_json
        self.quiet = quiet
        self.config_file = config_file  # kept for commands that merge more config in (run: the dataset's)
        self.overrides = overrides
        self.launch_args = launch_args or {}

    def summary(self, line: str, data: dict[str, Any]) -> None:
        """The one-line summary at the end of a command, or the JSON summary with ``--json``."""
        if self.as_json:
            from doorbatch.io.json_text import strict_json

            click.echo(strict_json(data))
        elif not self.quiet:
            click.echo(line)


def _setup_logging(verbosity: int) -> None:
    level = logging.WARNING - 10 * verbosity
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(levelname)s: %(message)s"))
    root = logging.getLogger("doorbatch")
    root.handlers[:] = [handler]
    root.setLevel(max(logging.DEBUG, min(logging.ERROR, level)))


def _output(folder: bool) -> Callable[[click.Context, click.Parameter, Path | None], Path | None]:
    """The ``-o`` callback of a command that writes a folder (``folder``) or one file: the location is checked
    before any work (:func:`~doorbatch.io.staged_dir.check_output_location`; an existing file or folder of the
    other kind is an error, never replaced)."""

    def check(_: click.Context, __: click.Parameter, value: Path | None) -> Path | None:
        from doorbatch.io.staged_dir import check_output_location

        if value is not None:
            check_output_location(value, folder=folder)
        return value

    return check


def _launch_args(_: click.Context, __: click.Parameter, values: tuple[str, ...]) -> dict[str, str]:
    """``--launch-arg name:=value`` (roslaunch's form) into a dict; the last of a name wins, as in roslaunch."""
    out: dict[str, str] = {}
    for text in values:
        name, sep, value = text.partition(":=")
        if not sep or not name.strip() or not value.strip() or ":=" in value:
            raise click.BadParameter(f"{text!r} is not NAME:=VALUE")
        out[name.strip()] = value.strip()
    return out


def common_options(func: F) -> F:
    """``--config``, ``--set``, ``-v/-q``, ``--json``; resolves the config into a :class:`Context`."""

    @click.option("--config", "config_file", type=click.Path(path_type=Path, dir_okay=False),
                  help="YAML merged over the defaults.")
    @click.option("--set", "overrides", multiple=True, metavar="SECTION.KEY=VALUE", help="Override one key.")
    @click.option("--launch-arg", "launch_args", multiple=True, metavar="NAME:=VALUE", callback=_launch_args,
                  help="An arg of the ROS 1 launch file given as --config, as roslaunch takes it (repeatable).")
    @click.option("-v", "--verbose", count=True, help="More log output (repeatable).")
    @click.option("-q", "--quiet", count=True, help="Less output.")
    @click.option("--json", "as_json", is_flag=True, help="Machine-readable summary on stdout.")
    @functools.wraps(func)
    def wrapper(config_file: Path | None, overrides: tuple[str, ...], launch_args: dict[str, str], verbose: int,
                quiet: int, as_json: bool, **kwargs: Any) -> Any:
        _setup_logging(verbose - quiet)
        set_progress_enabled(not quiet and not as_json)
        config = load_config(config_file, overrides, launch_args=launch_args)
        return func(Context(config, as_json, quiet > 0, config_file, overrides, launch_args), **kwargs)

    return wrapper  # type: ignore[return-value]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="doorbatch")
def cli() -> None:
    """doorbatch: door-aware maps, localization with door states, door poses and metrics from robot logs."""


@cli.command("inspect")
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=Path))
@common_options
def inspect_cmd(ctx: Context, log_path: Path) -> None:
    """Topics, types, counts, rates, duration, detected roles and problems of LOG."""
    from doorbatch.io.inspect import inspect_log
    from doorbatch.io.json_text import strict_json
    from doorbatch.progress import progress_bar

    with progress_bar(None, f"inspect {log_path.name}") as bar:
        report = inspect_log(log_path, ctx.config, progress=bar.update)
    if ctx.as_json:
        click.echo(strict_json(report.to_dict()))
    elif not ctx.quiet:
        click.echo(_format_report(report))
    if report.errors:
        first = report.errors[0]
        more = f" (+{len(report.errors) - 1} more)" if len(report.errors) > 1 else ""
        raise LogContentError(first.message + more, path=log_path, topic=first.topic)


def _format_report(report: Any) -> str:
    lines = [
        f"Files:      {report.path}",
        f"Storage:    {report.storage}",
        f"Size:       {report.size_bytes / 1024:.1f} KiB",
        f"Duration:   {report.duration_s:.3f} s",
        f"Start:      {report.start_ns / 1e9:.6f} s",
        f"End:        {report.end_ns / 1e9:.6f} s",
        f"Messages:   {report.message_count}",
        "Topics:",
    ]
    width = max((len(t.name) for t in report.topics), default=10)
    for t in report.topics:
        role = f"role {t.role} ({t.why})" if t.role else "unused" + (f" ({t.why})" if t.why else "")
        lines.append(f"  {t.name:<{width}}  {t.msgtype:<36} {t.count:>8} msgs {t.rate_hz:8.2f} Hz  {role}")
    lines.append(f"Frames:     {', '.join(report.frames) or '-'}")
    lines.append(f"Odometry:   {report.odometry}")
    lines.append(f"Reference:  {report.reference}")
    lines.append(f"Clock:      {report.clock}")
    lines.append(f"Laser:      {report.laser}")
    lines.append("Problems:" if report.problems else "Problems:   none")
    for p in report.problems:
        lines.append(f"  {p.severity.value:<7} {p.topic + ': ' if p.topic else ''}{p.message}")
    return "\n".join(lines)


@cli.command("convert")
@click.argument("source", metavar="IN", type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True, callback=_output(folder=False),
              help="Output .mcap file.")
@common_options
def convert_cmd(ctx: Context, source: Path, output: Path) -> None:
    """Convert a CARMEN log or a ROS 1/2 bag to MCAP (ROS 2 CDR)."""
    from doorbatch.io.convert import convert_log

    if output.suffix != ".mcap":
        raise click.BadParameter("the output must be a .mcap file", param_hint="-o")
    summary = convert_log(source, output, ctx.config)
    for warning in summary.warnings:
        log.warning("%s", warning)
    ctx.summary(f"converted {summary.messages} messages on {len(summary.topics)} topics from "
                f"{summary.storage} to {output}", asdict(summary))


@cli.command("simulate")
@click.argument("world", type=click.Path(path_type=Path, dir_okay=False))
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True,
              help="Output log: FILE.mcap, FILE.bag, or a folder for rosbag2.")
@click.option("--scenario", default=None, help="A scenario name in configs/scenarios/ or a YAML path.")
@click.option("--seed", type=click.IntRange(min=0), default=None, help="Random seed (default: the config's seed).")
@click.option("--format", "fmt", type=click.Choice(["mcap", "bag", "rosbag2", "rosbag2-mcap"]), default=None,
              help="Default: from the -o suffix (.mcap, .bag; none: a rosbag2 folder).")
@click.option("--split-passes", is_flag=True, help="Also write one log per pass (what doorbatch map takes).")
@common_options
def simulate_cmd(ctx: Context, world: Path, output: Path, scenario: str | None, seed: int | None, fmt: str | None,
                 split_passes: bool) -> None:
    """Simulate a log with ground truth in WORLD (a YAML file of configs/worlds/)."""
    from doorbatch.io.staged_dir import check_output_location
    from doorbatch.sim.simulate import run_simulation

    by_suffix = {".mcap": "mcap", ".bag": "bag"}.get(output.suffix.lower())
    if fmt is None:
        fmt = by_suffix or "rosbag2"
    elif (fmt in ("mcap", "bag") and by_suffix != fmt) or (fmt.startswith("rosbag2") and by_suffix is not None):
        raise UsageError(f"-o {output} does not fit --format {fmt} (.mcap for mcap, .bag for bag, a folder name "
                         f"without either suffix for rosbag2)")
    bag_folder = fmt.startswith("rosbag2")
    if bag_folder and output.is_dir() and any(output.iterdir()) and not (output / "metadata.yaml").is_file():
        raise UsageError(f"-o {output}: exists and is a folder that is not a ROS 2 bag (it would be replaced)")
    check_output_location(output, folder=bag_folder)  # a rosbag2 bag is a folder: never over a file

    summary = run_simulation(world, output, scenario, ctx.config.seed if seed is None else seed, fmt,
                             split_passes=split_passes)
    ctx.summary(f"simulated {summary.world}/{summary.scenario}: {summary.duration_s:.1f} s, "
                f"{sum(summary.message_counts.values())} messages, {summary.passes} pass"
                f"{'' if summary.passes == 1 else 'es'} → {summary.log_path}",
                summary.as_dict())


@cli.command("map")
@click.argument("logs", metavar="LOG...", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path, file_okay=False), required=True,
              callback=_output(folder=True),
              help="Map directory to write.")
@click.option("--pose-source", type=click.Choice(["reference", "odometry", "scanmatch"]), default=None,
              help="Where robot poses come from (default: reference if every log has one, else scanmatch).")
@click.option("--stages", default=None, help="Comma-separated stages: grid, em (default: grid,em when the logs "
              "have per-beam colours, else grid).")
@click.option("--classes", "classes_file", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="classes.json of an earlier em run: apply its class parameters without relearning.")
@click.option("--mcap", "mcap", is_flag=True, help="Also write MAPDIR/annotated.mcap: the passes' messages with "
              "the map, the doors of each pass, the poses, paths and map→odom.")
@common_options
def map_cmd(ctx: Context, logs: tuple[Path, ...], output: Path, pose_source: str | None, stages: str | None,
            classes_file: Path | None, mcap: bool) -> None:
    """Occupancy grid map with doors from LOG... (each log one pass; doors may move between passes)."""
    from doorbatch.pipeline.map_run import run_map
    from doorbatch.progress import progress_bar

    config = ctx.config
    if pose_source is not None:
        config = config.model_copy(update={"mapping": config.mapping.model_copy(update={"pose_source": pose_source})})
    with progress_bar(len(logs), "map", unit="pass") as bar:
        wanted = None if stages is None else [s.strip() for s in stages.split(",") if s.strip()]
        if wanted == []:
            raise UsageError(f"--stages {stages!r}: name grid, em or both")
        _, summary = run_map(list(logs), output, config, wanted, progress=bar.update, classes_file=classes_file,
                             mcap=mcap)
    ctx.summary(f"map of {summary.passes} pass(es) from {summary.pose_source} poses: {summary.doors} door(s) "
                f"→ {summary.map_dir}", asdict(summary))


@cli.command("localize")
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=Path))
@click.option("--map", "map_path", type=click.Path(path_type=Path), required=True,
              help="Map directory of doorbatch map, any map_server YAML, or a log with a /map OccupancyGrid.")
@click.option("-o", "--output", type=click.Path(path_type=Path, file_okay=False), required=True,
              callback=_output(folder=True),
              help="Run directory to write.")
@click.option("--method", type=click.Choice(["rbpf", "mcl"]), default=None, help="Default: localize.method.")
@click.option("--particles", type=click.IntRange(min=1), default=None,
              help="Maximum (and global-init) particle count.")
@click.option("--init", "init", default="reference", show_default=True,
              help="reference, global, X,Y,YAW, or a pose topic of LOG (/initialpose: its first message).")
@common_options
def localize_cmd(ctx: Context, log_path: Path, map_path: Path, output: Path, method: str | None,
                 particles: int | None, init: str) -> None:
    """Localize LOG on a map with MCL or the RBPF that estimates every door's angle."""
    from doorbatch.pipeline.localize.run import run_localize
    from doorbatch.progress import progress_bar

    lc = ctx.config.localize
    if particles is not None:
        lc = lc.model_copy(update={"max_particles": particles, "global_particles": particles,
                                   "min_particles": min(lc.min_particles, particles)})
    config = ctx.config.model_copy(update={"localize": lc})
    with progress_bar(None, f"localize: reading {log_path.name}", unit="scan") as bar:
        _, summary = run_localize(log_path, map_path, output, config, method or lc.method, init, bar)
    lost = ", ".join(f"{t:.1f}" for t in summary.lost_after_s)
    ctx.summary(f"{summary.method}: {summary.updates} updates, {summary.mean_particles:.0f} particles on average"
                f"{', ambiguous' if summary.ambiguous else ''}{f', lost at {lost} s' if lost else ''}"
                f" → {summary.run_dir}",
                asdict(summary))


@cli.command("evaluate")
@click.argument("run_dirs", metavar="RUNDIR...", nargs=-1, type=click.Path(path_type=Path))
@click.option("-o", "--output", type=click.Path(path_type=Path, file_okay=False), required=True,
              callback=_output(folder=True),
              help="Report directory to write.")
@click.option("--reference", type=click.Path(path_type=Path), default=None,
              help="Reference trajectory: a TUM file, a log with a reference pose topic, or LOG:/TOPIC.")
@click.option("--world", "truth", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="Simulator truth YAML (door map and door-state scoring).")
@click.option("--align", type=click.Choice(["none", "se2"]), default=None, help="Default: evaluate.align.")
@click.option("--experiment", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="Run an experiment sweep (configs/experiments/*.yaml) instead of evaluating RUNDIRs.")
@click.option("--workers", type=click.IntRange(min=1), default=1, show_default=True,
              help="Parallel processes for --experiment.")
@common_options
def evaluate_cmd(ctx: Context, run_dirs: tuple[Path, ...], output: Path, reference: Path | None,
                 truth: Path | None, align: str | None, experiment: Path | None, workers: int) -> None:
    """Metrics (APE/RPE as evo, convergence, door maps, door states) and a report of RUNDIRs, or an experiment.

    RUNDIRs are localize run directories, map directories, or other localizers' trajectories (with --reference):
    TUM files, or a log's pose topic as LOG:/TOPIC, e.g. AMCL's beside doorbatch's."""
    from doorbatch.errors import UsageError
    from doorbatch.io.report_writer import stdout_table

    config = ctx.config
    if align is not None:
        config = config.model_copy(update={"evaluate": config.evaluate.model_copy(update={"align": align})})
    if experiment is not None:
        from doorbatch.pipeline.evaluate.experiment import run_experiment_file

        evaluation = run_experiment_file(experiment, output, config, workers=workers)
    elif not run_dirs:
        raise UsageError("evaluate: give RUNDIR... or --experiment FILE")
    else:
        from doorbatch.pipeline.evaluate.stage import evaluate_run_dirs

        evaluation = evaluate_run_dirs(list(run_dirs), output, config, reference=reference, truth=truth)
    data = {"report_dir": str(output), "runs": len({r.run for r in evaluation.metrics}),
            "metrics": [{"run": r.run, "log": r.log, "method": r.method, "metric": r.metric, "value": r.value,
                         "unit": r.unit, "params": r.params} for r in evaluation.metrics]}
    if not ctx.as_json and not ctx.quiet:
        click.echo(stdout_table(evaluation))
    ctx.summary(f"{len(evaluation.metrics)} metrics of {data['runs']} runs → {output}/report.html", data)
@cli.command("doorpose")
@click.argument("log_path", metavar="LOG", type=click.Path(path_type=Path), required=False)
@click.option("-o", "--output", type=click.Path(path_type=Path, file_okay=False), required=True,
              callback=_output(folder=True),
              help="Run directory to write.")
@click.option("--map", "map_path", type=click.Path(path_type=Path), default=None,
              help="Map directory: match each door pose to a mapped door and report its angle.")
@click.option("--detector", default=None, help="topic, or a YOLO model file (.onnx, .pt TorchScript).")
@click.option("--fit", type=click.Choice(["ransac", "lsq", "naive"]), default=None, help="Default: doorpose.fit.")
@click.option("--simulate-approach", is_flag=True,
              help="Run a door pose experiment on simulated scenes instead; LOG is its file "
                   "(default configs/experiments/doorpose_table2.yaml).")
@common_options
def doorpose_cmd(ctx: Context, log_path: Path | None, output: Path, map_path: Path | None, detector: str | None,
                 fit: str | None, simulate_approach: bool) -> None:
    """Door poses from camera boxes fused with the laser (paper 003), goal poses in front of the doors."""
    from doorbatch.pipeline.doorpose.run import run_doorpose, run_simulated_experiment
    from doorbatch.progress import progress_bar
    from doorbatch.sim.scenario import configs_dir

    if simulate_approach:
        experiment = log_path or configs_dir() / "experiments" / "doorpose_table2.yaml"
        s = run_simulated_experiment(experiment, output, ctx.config)
        means = ", ".join(f"{k} {v:.4f}" for k, v in s.mean_error.items())
        ctx.summary(f"{s.experiment}, {s.samples} samples: mean summed error {means} → {s.run_dir}", asdict(s))
        return
    if log_path is None:
        raise UsageError("doorpose needs LOG (or --simulate-approach)")
    with progress_bar(None, "doorpose", unit="image") as bar:
        _, summary = run_doorpose(log_path, output, ctx.config, map_path, detector, fit, bar.update)
    ctx.summary(f"{summary.door_poses} door pose(s) from {summary.paired} image(s) paired with scans "
                f"({summary.fit}, frame {summary.frame}), {summary.matched} matched → {summary.run_dir}",
                asdict(summary))


@cli.command("run")
@click.argument("dataset", type=click.Path(path_type=Path, file_okay=False))
@click.option("-o", "--output", type=click.Path(path_type=Path, file_okay=False), required=True,
              callback=_output(folder=True),
              help="Output folder (maps, runs, reports, dataset tables, run.log).")
@click.option("--workers", type=click.IntRange(min=0), default=0, show_default=True,
              help="Parallel steps (0: one per CPU).")
@click.option("--executor", type=click.Choice(["local", "dask"]), default=None,
              help="local process pool (default), or a Dask cluster.")
@click.option("--scheduler", default=None, metavar="ADDRESS", help="Dask scheduler address (implies dask).")
@click.option("--force", is_flag=True, help="Redo every step, even those up to date.")
@common_options
def run_cmd(ctx: Context, dataset: Path, output: Path, workers: int, executor: str | None,
            scheduler: str | None, force: bool) -> None:
    """Map, localize and evaluate every site of DATASET (its dataset.yaml); incremental and cron-safe."""
    from doorbatch.errors import BatchPartialError
    from doorbatch.pipeline.batch.run import Execution, prepare_run, run_dataset

    execution = Execution("dask" if scheduler and executor is None else executor or "local", workers, scheduler)
    ds, config = prepare_run(dataset, ctx.config_file, ctx.overrides, ctx.launch_args)
    summary = run_dataset(ds, output, config, execution, force=force)
    ctx.summary(summary.line(), asdict(summary))
    if not summary.complete:
        first = summary.failures[0]
        raise BatchPartialError(f"{summary.failed + summary.blocked} of {summary.steps} steps did not complete "
                                f"(first: {first['step']}: {first['error']}); see {output / 'summary.json'}")


@cli.command("config")
@click.option("--dump", is_flag=True, help="Print the resolved configuration as YAML.")
@common_options
def config_cmd(ctx: Context, dump: bool) -> None:
    """Show the resolved configuration (defaults merged with --config and --set)."""
    import yaml

    if ctx.as_json:
        click.echo(json.dumps(ctx.config.as_dict(), indent=2))
    else:
        click.echo(yaml.safe_dump(ctx.config.as_dict(), sort_keys=False))


def main(argv: list[str] | None = None) -> int:
    """Console entry point: run the CLI, map errors to one line and an exit code. The ``doorbatch`` logger's
    level and handlers (set from ``-v/-q``) are restored afterwards, so that a library caller (or a test) that
    runs a command keeps its own logging."""
    logger = logging.getLogger("doorbatch")
    saved = (logger.level, list(logger.handlers))
    try:
        return _main(argv)
    finally:
        logger.setLevel(saved[0])
        logger.handlers[:] = saved[1]


def _main(argv: list[str] | None) -> int:
    try:
        with sigterm_as_interrupt():  # a kill unwinds like Ctrl-C: staged output removed, exit 130
            cli.main(args=argv, prog_name="doorbatch", standalone_mode=False)
    except DoorbatchError as err:
        click.echo(f"error: {err}", err=True)
        return int(err.exit_code)
    except click.exceptions.Exit as err:
        return int(err.exit_code)
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        return 130
    except click.ClickException as err:
        err.show()
        return int(ExitCode.USAGE)
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        return 130
    except Exception as err:  # a bug, or the machine's memory: one line here, the traceback in the crash log
        CRASH_LOG.write_text(traceback.format_exc())
        what = (f"out of memory ({err or 'MemoryError'}): a config value far from its default (a grid resolution, a "
                f"search step or window, a particle count) may ask for this much" if isinstance(err, MemoryError)
                else f"internal error ({type(err).__name__}: {err})")
        click.echo(f"error: {what}; traceback in {CRASH_LOG}", err=True)
        return 1
    return 0


def run() -> None:
    """Console script: exit with :func:`main`'s code."""
    sys.exit(main())


if __name__ == "__main__":
    run()
