"""doorbatch run end to end on a tiny dataset: outputs, dataset tables, incremental reruns, a corrupt log,
the lock, SIGTERM mid-way, and the Dask executor."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.dataset as pads
import pytest
import yaml

from doorbatch.cli import main
from doorbatch.io.manifest import utc_now_iso
from doorbatch.io.parquet import read_table
from doorbatch.io.run_lock import LOCK_NAME
from doorbatch.io.run_log import read_run_log
from tests.conftest import REPO
from tests.pipeline.batch.outputs import output_digests
from tests.pipeline.batch.tiny_dataset import LOCALIZATION, cut_log

SITE = "corridor"
METHODS = ("mcl", "rbpf")
ALL_STEPS = {f"map:{SITE}", f"evaluate:{SITE}", "report",
             *(f"localize:{SITE}/{log}/{m}" for log in LOCALIZATION for m in METHODS)}


def run_json(dataset: Path, out: Path, capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, dict]:
    code = main(["run", str(dataset), "-o", str(out), "--workers", "1", "--json", *args])
    return code, json.loads(capsys.readouterr().out)


def by_status(summary: dict, status: str) -> set[str]:
    return {o["step"] for o in summary["outcomes"] if o["status"] == status}


def test_run_writes_maps_runs_reports_and_hive_tables(reference_out: Path) -> None:
    out = reference_out
    assert (out / SITE / "map" / "map.yaml").is_file() and (out / SITE / "map" / "doors.parquet").is_file()
    # the map doorbatch map would build: the logs have beam colours, so the em stage too (run.map_stages null)
    assert json.loads((out / SITE / "map" / "manifest.json").read_text())["extra"]["stages"] == ["grid", "em"]
    assert (out / SITE / "map" / "walls.parquet").is_file()
    for log in LOCALIZATION:
        for method in METHODS:
            run = out / SITE / "runs" / log / method
            assert {p.name for p in run.iterdir()} >= {"trajectory.parquet", "door_states.parquet", "trajectory.tum",
                                                         "annotated.mcap", "manifest.json"}
    html = (out / "report" / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 2  # self-contained, with its plots
    for folder, stage in ((out / SITE / "report", "evaluate"), (out / "report", "report")):  # DESIGN: per-stage time
        assert json.loads((folder / "manifest.json").read_text())["stage_seconds"][stage] > 0.0
    # the dataset report's rows are per site: two sites' logs of one file name are never averaged together
    logs = set(read_table("metrics", out / "report" / "metrics.parquet").column("log").to_pylist()) - {""}
    assert logs == {f"{SITE}/{log}.mcap" for log in LOCALIZATION}
    metrics = pads.dataset(out / "metrics", format="parquet", partitioning="hive").to_table().to_pydict()
    assert set(metrics["site"]) == {SITE}
    ape = {(r, v) for r, m, v in zip(metrics["run"], metrics["metric"], metrics["value"], strict=True)
           if m == "ape_trans_rmse"}
    assert {r for r, _ in ape} == {f"{log}/{m}" for log in LOCALIZATION for m in METHODS}
    assert all(0.0 <= v < 0.5 for _, v in ape)  # tracking from the reference pose on the map it was built with
    trajectories = pads.dataset(out / "trajectories", format="parquet", partitioning="hive").to_table()
    assert set(trajectories.column("site").to_pylist()) == {SITE}
    assert set(trajectories.column("method").to_pylist()) == set(METHODS)
    events = read_run_log(out / "run.log")
    assert events[0]["event"] == "run_started" and events[-1]["event"] == "run_finished"
    assert {e["step"] for e in events if e.get("event") == "step_finished"} == ALL_STEPS
    summary = json.loads((out / "summary.json").read_text())
    assert summary["done"] == len(ALL_STEPS) and summary["failed"] == 0
    assert not (out / LOCK_NAME).exists()


def test_rerun_skips_everything_and_a_changed_log_redoes_only_its_steps(
        tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert run_json(tiny, out, capsys)[0] == 0
    before = output_digests(out, tiny)
    code, summary = run_json(tiny, out, capsys)
    assert code == 0 and by_status(summary, "up_to_date") == ALL_STEPS and summary["done"] == 0
    assert output_digests(out, tiny) == before

    cut_log("loc_open", tiny / "logs", 6.0)  # new content for one localization log
    code, summary = run_json(tiny, out, capsys)
    changed = {f"localize:{SITE}/loc_open/{m}" for m in METHODS} | {f"evaluate:{SITE}", "report"}
    assert code == 0 and by_status(summary, "done") == changed
    assert by_status(summary, "up_to_date") == ALL_STEPS - changed
    after = output_digests(out, tiny)
    assert after[f"{SITE}/map/map.pgm"] == before[f"{SITE}/map/map.pgm"]
    changed_run = f"{SITE}/runs/loc_open/mcl/trajectory.parquet"
    assert after[changed_run] != before[changed_run]

    # a localization parameter redoes localization and evaluation, not the map; --force redoes all
    code, summary = run_json(tiny, out, capsys, "--set", "localize.sigma_hit=0.12")
    assert code == 0 and by_status(summary, "up_to_date") == {f"map:{SITE}"}
    code, summary = run_json(tiny, out, capsys, "--set", "localize.sigma_hit=0.12", "--force")
    assert code == 0 and by_status(summary, "done") == ALL_STEPS

    # a mapping setting that leaves the map as it was redoes the map only (every localization redid before)
    sets = ["--set", "localize.sigma_hit=0.12", "--set", "mapping.odometry_continuity_m=2.0"]
    code, summary = run_json(tiny, out, capsys, *sets)
    assert code == 0 and by_status(summary, "done") == {f"map:{SITE}"}

    # outputs deleted since are made again, not taken as done (the site's evaluation had failed every night)
    (out / SITE / "runs" / "loc_open" / "mcl" / "trajectory.parquet").unlink()
    (out / "report" / "report.html").unlink()
    code, summary = run_json(tiny, out, capsys, *sets)
    assert code == 0 and by_status(summary, "done") == {f"localize:{SITE}/loc_open/mcl", "report"}
    assert (out / "report" / "report.html").is_file()
    shutil.rmtree(out / "metrics")
    code, summary = run_json(tiny, out, capsys, *sets)
    assert code == 0 and by_status(summary, "done") == {"report"} and (out / "metrics").is_dir()


def test_corrupt_log_fails_its_steps_and_the_rest_completes(
        tiny: Path, tiny_master: Path, tmp_path: Path, reference_out: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tiny / "logs" / "loc_open.mcap"
    data = log.read_bytes()
    n = len(data)
    log.write_bytes(data[: n // 2] + bytes(4096) + data[n // 2 + 4096:])  # a corrupt chunk mid-file
    out = tmp_path / "out"
    code, summary = run_json(tiny, out, capsys)
    assert code == 4
    failed = {f"localize:{SITE}/loc_open/{m}" for m in METHODS}
    assert {f["step"] for f in summary["failures"]} == failed
    assert all(str(log) in f["error"] for f in summary["failures"])
    assert by_status(summary, "done") == ALL_STEPS - failed
    assert json.loads((out / "summary.json").read_text())["failures"] == summary["failures"]
    # every other output complete, and equal to the uninterrupted run's
    ours, theirs = output_digests(out, tiny), output_digests(reference_out, tiny_master)
    for rel in ("map/map.pgm", "runs/loc_closed/rbpf/trajectory.parquet", "runs/loc_closed/mcl/annotated.mcap"):
        assert ours[f"{SITE}/{rel}"] == theirs[f"{SITE}/{rel}"]
    assert not [p for p in (out / SITE / "runs").rglob("*") if p.is_file() and "loc_open" in p.parts]
    metrics = pads.dataset(out / "metrics", format="parquet", partitioning="hive").to_table()
    assert {r for r in metrics.column("run").to_pylist() if "/" in r and "map" not in r} == {
        f"loc_closed/{m}" for m in METHODS}
    # the reports a person reads name what they lack: the site's and the dataset's, in md and html
    for report in (out / SITE / "report", out / "report"):
        for name in ("report.md", "report.html"):
            text = (report / name).read_text()
            assert "Left out" in text and all(step in text for step in failed), report / name
    # the user drops the bad log: the reports are made again, without it (what they lack is part of their key)
    dataset = yaml.safe_load((tiny / "dataset.yaml").read_text())
    site = dataset["sites"][SITE]
    site["localization"] = [p for p in site["localization"] if "loc_open" not in p]
    (tiny / "dataset.yaml").write_text(yaml.safe_dump(dataset, sort_keys=False))
    code, _ = run_json(tiny, out, capsys)
    assert code == 0
    for report in (out / SITE / "report", out / "report"):
        assert "loc_open" not in (report / "report.md").read_text()


def test_a_live_lock_is_exit_2_and_a_stale_one_is_taken_over(
        tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    out.mkdir()
    holder = {"pid": os.getpid(), "host": socket.gethostname(), "started_at": utc_now_iso()}
    (out / LOCK_NAME).write_text(json.dumps(holder))
    assert main(["run", str(tiny), "-o", str(out), "-q"]) == 2
    assert f"pid {os.getpid()}" in capsys.readouterr().err
    assert not (out / "run.log").exists()

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True,
                          check=True)
    (out / LOCK_NAME).write_text(json.dumps({**holder, "pid": int(gone.stdout)}))
    code = main(["run", str(tiny), "-o", str(out), "-q", "--set", "run.methods=[mcl]"])
    assert code == 0 and not (out / LOCK_NAME).exists()
    assert [e["holder"] for e in read_run_log(out / "run.log") if e.get("event") == "stale_lock"] == [
        f"pid {gone.stdout.strip()} on {holder['host']} since {holder['started_at']}"]


def test_sigterm_midway_leaves_no_partial_output_and_a_rerun_matches(
        tiny: Path, tiny_master: Path, tmp_path: Path, reference_out: Path) -> None:
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "doorbatch.cli", "run", str(tiny), "-o", str(out), "--workers", "1", "-q"]
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:  # kill once the map is done: mid-localization
        log = out / "run.log"
        if log.exists() and '"step_finished"' in log.read_text():
            break
        time.sleep(0.02)
    proc.send_signal(signal.SIGTERM)
    # 130 from doorbatch's handler; rarely CPython itself re-raises the handled interrupt as SIGINT at exit
    # (seen once in 4 CI runs after "aborted" was printed), which a shell reports as 130 too.
    assert proc.wait(60) in (130, -signal.SIGINT), proc.stderr.read() if proc.stderr else ""
    assert not [p for p in out.rglob("*") if ".tmp" in p.name or p.name.endswith(".old")]
    assert not (out / LOCK_NAME).exists() and not (out / "report").exists()
    assert read_run_log(out / "run.log")[-1]["event"] == "run_interrupted"
    assert json.loads((out / "summary.json").read_text())["status"] == "interrupted"  # not the last run's summary
    for run in (out / SITE / "runs").glob("*/*") if (out / SITE / "runs").exists() else []:
        assert (run / "manifest.json").is_file()  # a run folder is there only when complete

    assert subprocess.run(cmd, env=env, capture_output=True, check=False).returncode == 0
    assert output_digests(out, tiny) == output_digests(reference_out, tiny_master)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "finished" and summary["started_at"] < summary["finished_at"]


@pytest.mark.parametrize("name", ["report", "metrics", "trajectories"])
def test_a_site_named_like_the_batchs_own_outputs_is_refused_before_writing(tiny: Path, tmp_path: Path, name: str,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    dataset = tiny / "dataset.yaml"
    dataset.write_text(dataset.read_text().replace("corridor:", f"{name}:", 1))
    out = tmp_path / "out"
    code = main(["run", str(tiny), "-o", str(out), "-q"])
    assert code == 2 and f"site name '{name}'" in capsys.readouterr().err
    assert not out.exists()


def test_a_config_typo_in_dataset_yaml_names_the_file(tiny: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    dataset = yaml.safe_load((tiny / "dataset.yaml").read_text())
    dataset["config"]["localize"]["sigma_hitt"] = 0.1
    (tiny / "dataset.yaml").write_text(yaml.safe_dump(dataset))
    code = main(["run", str(tiny), "-o", str(tmp_path / "out"), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "dataset.yaml (config:)" in err and "did you mean 'localize.sigma_hit'" in err


def test_an_unreachable_dask_scheduler_is_a_usage_error(tiny: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("distributed")
    from doorbatch.pipeline.batch import executors

    monkeypatch.setattr(executors, "SCHEDULER_TIMEOUT_S", 0.5)
    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    code = main(["run", str(tiny), "-o", str(tmp_path / "out"), "--scheduler", f"tcp://127.0.0.1:{port}", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "cannot reach a Dask scheduler" in err and "internal error" not in err


def test_dask_executor_gives_the_local_outputs(tiny: Path, tiny_master: Path, tmp_path: Path,
                                               reference_out: Path) -> None:
    pytest.importorskip("distributed")
    out = tmp_path / "out"
    assert main(["run", str(tiny), "-o", str(out), "--executor", "dask", "--workers", "2", "-q"]) == 0
    assert output_digests(out, tiny) == output_digests(reference_out, tiny_master)
    assert read_run_log(out / "run.log")[0]["executor"] == "dask"


def test_an_out_that_holds_the_datasets_logs_where_a_step_writes_is_refused(tiny: Path,
                                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """OUT = the dataset folder, whose site keeps its passes in <site>/map/: the map step replaces OUT/<site>/map
    whole, and would delete the logs. Refused before anything is written; the logs stay."""
    (tiny / SITE / "map").mkdir(parents=True)
    shutil.move(tiny / "logs" / "map_pass1.mcap", tiny / SITE / "map" / "map_pass1.mcap")
    dataset = tiny / "dataset.yaml"
    dataset.write_text(dataset.read_text().replace("logs/map_pass1.mcap", f"{SITE}/map/map_pass1.mcap"))
    before = sorted(p.relative_to(tiny) for p in tiny.rglob("*"))
    code = main(["run", str(tiny), "-o", str(tiny), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and f"{SITE}/map/map_pass1.mcap lies inside it" in err
    assert sorted(p.relative_to(tiny) for p in tiny.rglob("*")) == before


@pytest.mark.parametrize("foreign", ["report/q3.pptx", f"{SITE}/runs/loc_open/mcl/notes.txt", "metrics/summary.csv",
                                     "trajectories/site=corridor/extra.parquet"])
def test_an_out_whose_folders_hold_files_the_run_did_not_write_is_refused(
        tiny: Path, tmp_path: Path, foreign: str, capsys: pytest.CaptureFixture[str]) -> None:
    """A shared OUT where someone keeps a file in a folder the run replaces whole: refused, the file kept."""
    out = tmp_path / "out"
    (out / foreign).parent.mkdir(parents=True)
    (out / foreign).write_text("not doorbatch's")
    code = main(["run", str(tiny), "-o", str(out), "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "did not write" in err and foreign.split("/")[-1] in err
    assert (out / foreign).read_text() == "not doorbatch's"


def test_a_file_added_to_a_folder_the_run_wrote_is_not_deleted_by_the_next_run(
        tiny_master: Path, reference_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """notes.md added to OUT/report after a run: the step's record does not list it, so the next run refuses
    (a rerun of the report would replace the folder whole) and the file stays."""
    out = Path(shutil.copytree(reference_out, tmp_path / "out"))
    (out / "report" / "notes.md").write_text("mine")
    code = main(["run", str(tiny_master), "-o", str(out), "-q", "--force"])
    assert code == 2 and "notes.md" in capsys.readouterr().err
    assert (out / "report" / "notes.md").read_text() == "mine"


def test_a_rerun_into_its_own_out_is_not_refused_and_keeps_a_users_dotfiles(
        tiny_master: Path, reference_out: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OUT written by doorbatch run is its own (a rerun does nothing); `.notes.old` and `.cache.tmp` beside its
    outputs are not a killed run's staged folders and stay."""
    out = Path(shutil.copytree(reference_out, tmp_path / "out"))
    for name in (".notes.old", f"{SITE}/.cache.tmp"):
        (out / name).write_text("mine")
    code, summary = run_json(tiny_master, out, capsys)
    assert code == 0 and by_status(summary, "up_to_date") == ALL_STEPS
    assert (out / ".notes.old").read_text() == "mine" and (out / SITE / ".cache.tmp").read_text() == "mine"


def test_a_rerun_with_other_doorbatch_code_redoes_every_step(tiny_master: Path, reference_out: Path, tmp_path: Path,
                                                             monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """An upgrade keeps the version number (0.1.0 across commits) and the config: the steps are keyed on the hash of
    doorbatch's source too, so results of the old code are not taken as up to date."""
    from doorbatch.pipeline.batch import freshness

    out = Path(shutil.copytree(reference_out, tmp_path / "out"))
    monkeypatch.setattr(freshness, "code_fingerprint", lambda: "0" * 64)
    code, summary = run_json(tiny_master, out, capsys)
    assert code == 0 and by_status(summary, "done") == ALL_STEPS
    record = json.loads((out / SITE / "map" / "manifest.json").read_text())["extra"]["step"]
    assert record["code_sha256"] == "0" * 64


def test_a_file_where_a_sites_folder_must_go_fails_its_steps_as_the_machines_fault(
        tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """OUT/<site> is a file: each of the site's steps fails naming what is in the way (exit 4), not as an
    "internal error" (a bug's wording; the docs promise exit 1 for those)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / SITE).write_text("in the way")
    code, summary = run_json(tiny, out, capsys)
    assert code == 4
    errors = {f["step"]: f["error"] for f in summary["failures"] if f["status"] == "failed"}
    assert errors[f"map:{SITE}"].startswith("file system: File exists") and SITE in errors[f"map:{SITE}"]
    assert not any("internal error" in e for e in errors.values())


def test_a_log_cut_off_mid_write_is_named_in_summary_json(tiny: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A log still being written when cron fired (an MCAP cut off mid-chunk, no summary section) is read up to the
    cut: its steps succeed, and summary.json's outcomes carry the reader's warning (with -q nothing else says so)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    log = tiny / "logs" / "loc_open.mcap"
    with log.open("rb") as f:  # in small chunks, as a recorder writes a long log: the cut leaves most of them
        reader = make_reader(f)
        messages = list(reader.iter_messages())
    with (tmp_path / "chunked.mcap").open("wb") as f:
        writer = Writer(f, chunk_size=4096)
        writer.start(profile="ros2", library="a recorder")
        schemas: dict[int, int] = {}
        channels: dict[int, int] = {}
        for schema, channel, message in messages:
            if schema is not None and schema.id not in schemas:
                schemas[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = writer.register_channel(channel.topic, channel.message_encoding,
                                                               schemas.get(channel.schema_id, 0), channel.metadata)
            writer.add_message(channels[channel.id], message.log_time, message.data, message.publish_time)
        writer.finish()
    data = (tmp_path / "chunked.mcap").read_bytes()
    log.write_bytes(data[: int(len(data) * 0.8)])
    code, printed = run_json(tiny, tmp_path / "out", capsys)
    assert code == 0 and printed == json.loads((tmp_path / "out" / "summary.json").read_text())
    said = {o["step"]: o.get("warnings", []) for o in printed["outcomes"]}
    assert any("no summary section" in w for w in said[f"localize:{SITE}/loc_open/mcl"])
    assert not any("no summary section" in w for w in said[f"localize:{SITE}/loc_closed/mcl"])


def test_a_pattern_over_a_folder_that_holds_out_leaves_the_runs_own_outputs_out(
        tiny: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """localization: nightly/**/*.mcap with OUT = nightly/out: the second night the pattern also matches the first
    night's annotated.mcap files; they are left out (a folder with a run's run.log and summary.json is its OUT),
    and the rerun does nothing."""
    (tiny / "nightly").mkdir()
    for name in LOCALIZATION:
        shutil.move(tiny / "logs" / f"{name}.mcap", tiny / "nightly" / f"{name}.mcap")
        for suffix in (".truth.tum", ".truth.yaml"):
            if (tiny / "logs" / f"{name}{suffix}").exists():
                shutil.move(tiny / "logs" / f"{name}{suffix}", tiny / "nightly" / f"{name}{suffix}")
    dataset = yaml.safe_load((tiny / "dataset.yaml").read_text())
    dataset["sites"][SITE]["localization"] = ["nightly/**/*.mcap"]
    (tiny / "dataset.yaml").write_text(yaml.safe_dump(dataset))
    out = tiny / "nightly" / "out"
    code, first = run_json(tiny, out, capsys)
    assert code == 0 and len(by_status(first, "done")) == len(ALL_STEPS)
    assert list(out.rglob("annotated.mcap"))
    code, second = run_json(tiny, out, capsys)
    assert code == 0 and by_status(second, "up_to_date") == ALL_STEPS
