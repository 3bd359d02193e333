"""evaluate_runs and doorbatch evaluate: known answers on synthetic runs, the report directory's contents."""

from __future__ import annotations

import base64
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.io.manifest import Manifest
from doorbatch.io.parquet import read_table
from doorbatch.io.rundir import write_run_tables
from doorbatch.io.sim_truth import SimTruth, TruthDoor
from doorbatch.io.tum import write_tum
from doorbatch.maps import DoorSet
from doorbatch.pipeline.evaluate.door_state_error import door_state_errors
from doorbatch.pipeline.evaluate.report import (
    ReferenceTrajectory,
    RunTables,
    evaluate_runs,
    run_tables_from_result,
    summary_table,
)
from doorbatch.pipeline.localize.result import LocalizationResult
from tests.conftest import REPO

T0 = 1_700_000_000_000_000_000
SAMPLE_LOGS = REPO / "datasets" / "sample" / "logs"
DT = 100_000_000


def _straight(n: int = 200) -> tuple[np.ndarray, np.ndarray]:
    """A robot driving along x at 0.5 m/s, 10 Hz."""
    stamps = T0 + DT * np.arange(n, dtype=np.int64)
    pose = np.stack([0.05 * np.arange(n), np.zeros(n), np.zeros(n)], axis=1)
    return stamps, pose


def _truth(angle_rad: float) -> SimTruth:
    door = TruthDoor(0, "d0", 5.0, 1.0, 0.9, 0.0, 1, 1.5, 2.0, (0.5, 0.5, 0.5), (0.1, 0.1, 0.1))
    return SimTruth(generator={}, start_ns=T0, end_ns=T0 + 100 * DT, files={}, world_name="w", wall_height_m=2.0,
                    segments=np.zeros((0, 2, 2)), segment_kinds=(), doors=(door,), passes=(),
                    angle_stamp_ns=np.array([T0, T0 + 100 * DT]), angle_door_id=np.array([0, 0]),
                    angle_rad=np.array([0.0, angle_rad]))


def test_known_offset_gives_known_ape_and_zero_rpe() -> None:
    stamps, ref = _straight()
    est = ref + np.array([0.0, 0.1, 0.02])
    run = RunTables("r", "log.mcap", "mcl", stamps, est, reference=ReferenceTrajectory(stamps, ref))
    ev = evaluate_runs([run], DoorbatchConfig())
    for stat in ("rmse", "mean", "median", "min", "max"):
        assert ev.value("r", f"ape_trans_{stat}") == pytest.approx(0.1, abs=1e-12)
        assert ev.value("r", f"ape_rot_{stat}") == pytest.approx(0.02, abs=1e-12)
    assert ev.value("r", "ape_trans_std") == pytest.approx(0.0, abs=1e-12)
    # a constant heading offset turns every relative motion d by 0.02 rad: ‖E‖ = 2 sin(0.01) d, d ≈ 1 m
    assert ev.value("r", "rpe_trans_max") == pytest.approx(2 * math.sin(0.01) * 1.0, rel=0.06)
    assert ev.value("r", "rpe_rot_max") == pytest.approx(0.0, abs=1e-12)
    assert ev.value("r", "rpe_pairs") == 9  # 9.95 m of path in 1 m steps
    shifted = RunTables("s", "log.mcap", "mcl", stamps, ref + np.array([0.3, -0.1, 0.0]),
                        reference=ReferenceTrajectory(stamps, ref))
    assert evaluate_runs([shifted], DoorbatchConfig()).value("s", "rpe_trans_max") == pytest.approx(0.0, abs=1e-12)
    aligned = evaluate_runs([run], load_config(overrides=["evaluate.align=se2", "evaluate.angle_unit=deg"]))
    assert aligned.value("r", "ape_trans_max") < 1e-9  # SE(2) alignment removes the offset
    assert next(r.unit for r in aligned.metrics if r.metric == "ape_rot_rmse") == "deg"


def test_global_success_needs_convergence_at_the_right_pose() -> None:
    stamps, ref = _straight()
    reference = ReferenceTrajectory(stamps, ref)
    turned = ref.copy()
    turned[:, 2] = np.pi  # converged on the pose turned by 180° (the symmetric corridor's trap)
    near = ref + np.array([0.05, 0, 0])
    runs = [RunTables("ok", "l", "rbpf", stamps, near, init="global", converged_ns=int(stamps[20])),
            RunTables("turned", "l", "rbpf", stamps, turned, init="global", converged_ns=int(stamps[20])),
            RunTables("late", "l", "rbpf", stamps, ref, init="global", converged_ns=None),
            RunTables("tracking", "l", "rbpf", stamps, ref, init="reference", converged_ns=int(stamps[0]))]
    ev = evaluate_runs(runs, DoorbatchConfig(), reference=reference)
    assert [ev.value(n, "global_success") for n in ("ok", "turned", "late")] == [1.0, 0.0, 0.0]
    assert math.isnan(ev.value("tracking", "global_success"))
    assert ev.value("ok", "time_to_converge_s") == pytest.approx(2.0)
    assert math.isnan(ev.value("late", "time_to_converge_s")) and ev.value("late", "converged") == 0.0


def test_global_success_is_judged_after_the_alignment_asked_for() -> None:
    """A run localized on a map in another frame (built from scan matching, in the odometry's frame): with
    --align se2 its APE is taken after the alignment, and so must its global success be (it was 0 % for runs that
    tracked within 2 cm once aligned)."""
    from doorbatch.geometry.se2 import compose

    stamps, ref = _straight()
    ref = ref + np.stack([np.zeros(len(ref)), np.sin(ref[:, 0]), np.zeros(len(ref))], axis=1)  # not a line
    frame = np.array([3.0, -2.0, 0.7])  # the map's frame in the reference's
    estimate = compose(np.broadcast_to(-frame, ref.shape), ref)  # not the inverse: any rigid motion will do
    run = RunTables("other_frame", "l", "mcl", stamps, estimate, init="global", converged_ns=int(stamps[20]))
    reference = ReferenceTrajectory(stamps, ref)
    plain = evaluate_runs([run], DoorbatchConfig(), reference=reference)
    assert plain.value("other_frame", "global_success") == 0.0
    assert len(plain.warnings) == 1 and "--align se2" in plain.warnings[0]  # the user hears why, and the fix
    # a global start may as well have locked on the wrong one of two similar places: the hint says both, and that
    # aligning is right only for a map in another frame (aligning a wrong lock away would score it a success)
    assert "locked on the wrong one of two similar places" in plain.warnings[0]
    assert "right only for the latter" in plain.warnings[0]
    tracked = evaluate_runs([replace(run, init="reference")], DoorbatchConfig(), reference=reference)
    assert "locked" not in tracked.warnings[0] and "scores it in the reference's" in tracked.warnings[0]
    aligned = evaluate_runs([run], load_config(overrides=["evaluate.align=se2"]), reference=reference)
    assert aligned.value("other_frame", "ape_trans_max") < 1e-9
    assert aligned.value("other_frame", "global_success") == 1.0
    # the alignment is reported, so that a run turned by 180° (or any wrong frame) shows
    back = compose(np.broadcast_to([aligned.value("other_frame", f"alignment_{k}") for k in ("x", "y", "yaw")],
                                   estimate.shape), estimate)
    np.testing.assert_allclose(back, ref, atol=1e-9)
    assert not aligned.warnings


def test_a_run_stamped_late_is_matched_after_t_offset_and_a_sparse_match_is_told() -> None:
    """A localizer that stamped 0.3 s late (another clock): at evo's default tolerance its poses meet the wrong
    reference poses, 0.15 m off along the drive; --t_offset -0.3 (evaluate.t_offset_s) puts them back. A
    reference of which only every 4th stamp is within the tolerance leaves a quarter of the poses: a warning."""
    stamps, ref = _straight()
    late = RunTables("late", "l", "mcl", stamps + 300_000_000, ref)
    reference = ReferenceTrajectory(stamps, ref)
    plain = evaluate_runs([late], DoorbatchConfig(), reference=reference)
    assert plain.value("late", "ape_trans_mean") == pytest.approx(0.15, abs=1e-9)
    shifted = evaluate_runs([late], load_config(overrides=["evaluate.t_offset_s=-0.3"]), reference=reference)
    assert shifted.value("late", "ape_trans_max") == pytest.approx(0.0, abs=1e-9)
    assert not plain.warnings and not shifted.warnings
    sparse = evaluate_runs([RunTables("dense", "l", "mcl", stamps, ref)], DoorbatchConfig(),
                           reference=ReferenceTrajectory(stamps[::4], ref[::4]))
    assert sparse.value("dense", "associated_poses") == 50
    assert len(sparse.warnings) == 1 and "only 50 of its 200 poses" in sparse.warnings[0]
    assert "400 ms apart" in sparse.warnings[0] and "evaluate.max_time_diff_s=0.2 " in sparse.warnings[0]


def test_a_run_that_covers_a_sliver_of_its_reference_is_told() -> None:
    """One pose (a filter that made one update over a log whose odometry never moved) against a 20 s reference:
    its APE is a number, but it describes 0 s of the log: a warning names both spans. The whole run: none."""
    stamps, ref = _straight()
    reference = ReferenceTrajectory(stamps, ref)
    one = evaluate_runs([RunTables("one", "l", "rbpf", stamps[:1], ref[:1])], DoorbatchConfig(), reference=reference)
    assert one.value("one", "associated_poses") == 1
    assert any("its 1 pose(s) span 0.0 s of the reference's 19.9 s" in w for w in one.warnings), one.warnings
    half = evaluate_runs([RunTables("part", "l", "rbpf", stamps[:120], ref[:120])], DoorbatchConfig(),
                         reference=reference)
    assert not half.warnings


def test_a_25_hz_truth_is_interpolated_at_10_hz_updates_when_asked() -> None:
    """Filter updates at scan stamps 13 ms past a 25 Hz truth's, the estimate exactly on the truth, 1 m/s: evo's
    0.01 s pairs some updates (a warning says so), 0.02 s pairs all but up to 20 ms off (2 cm); the reference
    interpolated at each update's stamp scores all of them at their own time: no error."""
    t_ref = T0 + 40_000_000 * np.arange(250, dtype=np.int64)
    ref = np.stack([(t_ref - T0) / 1e9, np.zeros(250), np.zeros(250)], axis=1)  # 1 m/s along x
    t_run = T0 + 13_000_000 + 100_000_000 * np.arange(90, dtype=np.int64)
    run = RunTables("r", "l", "mcl", t_run, np.stack([(t_run - T0) / 1e9, np.zeros(90), np.zeros(90)], axis=1))
    reference = ReferenceTrajectory(t_ref, ref)
    evo = evaluate_runs([run], DoorbatchConfig(), reference=reference)
    assert evo.value("r", "associated_poses") < 60 and len(evo.warnings) == 1
    assert "reference_at_run_stamps=true" in evo.warnings[0]
    wide = evaluate_runs([run], load_config(overrides=["evaluate.max_time_diff_s=0.02"]), reference=reference)
    assert wide.value("r", "associated_poses") == 90 and wide.value("r", "ape_trans_max") > 0.01
    at = evaluate_runs([run], load_config(overrides=["evaluate.reference_at_run_stamps=true"]), reference=reference)
    assert at.value("r", "associated_poses") == 90 and at.value("r", "ape_trans_max") < 1e-9 and not at.warnings


def test_a_robot_that_stood_still_far_off_is_scored_without_a_frame_hint() -> None:
    """No rigid motion can be fitted to poses that never move; the APE stands, no hint, no error."""
    stamps, ref = _straight(50)
    ref[:] = ref[0]
    ev = evaluate_runs([RunTables("still", "l", "mcl", stamps, ref + np.array([3.0, 0.0, 0.0]))], DoorbatchConfig(),
                       reference=ReferenceTrajectory(stamps, ref))
    assert ev.value("still", "ape_trans_rmse") == pytest.approx(3.0) and not ev.warnings


def test_a_lost_run_is_not_taken_for_another_frame() -> None:
    """A run that wandered off (no rigid motion explains its error) gets no frame hint."""
    stamps, ref = _straight()
    rng = np.random.default_rng(0)
    lost = ref + np.cumsum(rng.normal(0.0, [0.3, 0.3, 0.05], ref.shape), axis=0)
    ev = evaluate_runs([RunTables("lost", "l", "mcl", stamps, lost)], DoorbatchConfig(),
                       reference=ReferenceTrajectory(stamps, ref))
    assert ev.value("lost", "ape_trans_rmse") > 1.0 and not ev.warnings


def test_global_success_interpolates_a_reference_at_its_own_rate() -> None:
    """A ground truth at 25 Hz has no pose at a 10 Hz scan's stamp half of the time (20 ms off): the check
    interpolates it instead of failing the run; a reference that stops early still fails it."""
    stamps, ref = _straight()
    t25 = T0 + 40_000_000 * np.arange(500, dtype=np.int64)  # 25 Hz over the same 20 s
    ref25 = np.stack([0.5 * (t25 - T0) / 1e9, np.zeros(500), np.zeros(500)], axis=1)
    run = RunTables("ok", "l", "rbpf", stamps, ref + np.array([0.05, 0, 0]), init="global",
                    converged_ns=int(stamps[21]))  # 2.1 s and the last update (19.9 s): 20 ms from any truth pose
    assert evaluate_runs([run], DoorbatchConfig(), reference=ReferenceTrajectory(t25, ref25)).value(
        "ok", "global_success") == 1.0
    short = ReferenceTrajectory(t25[:100], ref25[:100])  # no reference at the end of the run
    assert evaluate_runs([run], DoorbatchConfig(), reference=short).value("ok", "global_success") == 0.0


def test_door_state_error_counts_recently_observed_doors_only() -> None:
    truth = _truth(math.radians(40))
    stamps = T0 + DT * np.arange(100, dtype=np.int64)
    true_angle = truth.door_angles_at(stamps)[:, 0]
    map_doors = DoorSet(np.array([[5.05, 1.0]]), np.array([0.9]), np.array([0.1]), np.zeros(1), np.ones(1))
    est = true_angle - 0.1 + math.radians(5)  # map closed_yaw is 0.1 rad off: global direction 5° off
    observed = np.arange(100) < 50  # observed for 5 s, then unseen
    errs = door_state_errors(stamps, np.zeros(100, np.int32), est, observed, map_doors, truth, 0.3, 2 * 10**9)
    assert errs.stamps_ns[0] == stamps[0] and errs.stamps_ns[-1] == stamps[69]  # 2 s after the last observation
    np.testing.assert_allclose(errs.error_rad, math.radians(5), atol=1e-12)
    far = DoorSet(np.array([[6.0, 1.0]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.ones(1))
    assert door_state_errors(stamps, np.zeros(100, np.int32), est, observed, far, truth, 0.3, 0).error_rad.size == 0


def test_door_state_error_over_all_matched_doors_shows_doors_never_observed() -> None:
    """A loc_open RBPF run showed door_state_error_mean 2.4° while two doors sat 136° and 59° off: never observed
    (their true angle lies outside the mapped range), they never counted. door_state_error_all_mean counts every
    matched door at every update; door_state_error_mean keeps its definition."""
    from doorbatch.io.sim_truth import TruthDoor
    from doorbatch.pipeline.evaluate.report import DoorStateTable

    doors = tuple(TruthDoor(k, f"d{k}", 5.0 * (k + 1), 1.0, 0.9, 0.0, 1, 1.5, 2.0, (0.5,) * 3, (0.1,) * 3)
                  for k in range(3))
    truth = SimTruth(generator={}, start_ns=T0, end_ns=T0 + 100 * DT, files={}, world_name="w", wall_height_m=2.0,
                     segments=np.zeros((0, 2, 2)), segment_kinds=(), doors=doors, passes=(),
                     angle_stamp_ns=np.full(3, T0), angle_door_id=np.arange(3), angle_rad=np.zeros(3))
    map_doors = DoorSet(np.array([[5.0, 1.0], [10.0, 1.0], [15.0, 1.0]]), np.full(3, 0.9), np.zeros(3), np.zeros(3),
                        np.full(3, 0.5))
    stamps, ref = _straight(50)
    off = np.radians([2.0, 136.0, 59.0])
    states = DoorStateTable(np.repeat(stamps, 3), np.tile(np.arange(3, dtype=np.int32), 50), np.tile(off, 50),
                            np.tile([True, False, False], 50))
    run = RunTables("r", "loc_open.mcap", "rbpf", stamps, ref, door_states=states, map_doors=map_doors, truth=truth)
    ev = evaluate_runs([run], DoorbatchConfig())
    assert ev.value("r", "door_state_error_mean") == pytest.approx(math.radians(2.0))
    assert ev.value("r", "door_state_error_all_mean") == pytest.approx(np.mean(off))
    assert next(r.unit for r in ev.metrics if r.metric == "door_state_error_all_mean") == "rad"
    assert "door_state_error_all_mean" in summary_table(ev).value_columns
    unseen = replace(run, door_states=replace(states, observed=np.zeros(150, dtype=bool)))  # no door ever observed
    ev = evaluate_runs([unseen], DoorbatchConfig())
    assert math.isnan(ev.value("r", "door_state_error_mean"))
    assert ev.value("r", "door_state_error_all_mean") == pytest.approx(np.mean(off))
    # The truth of another log (the mapping log's, given to --world for a localization run; an outside user's): its
    # door angles were scored against the run's without a word. Its time span says so.
    mapping_log = replace(truth, start_ns=T0 - 3600 * 10**9, end_ns=T0 - 3000 * 10**9, files={"log": "map.mcap"})
    ev = evaluate_runs([run], DoorbatchConfig(), truth=mapping_log)
    assert math.isnan(ev.value("r", "door_state_error_mean")) and math.isnan(ev.value("r", "door_state_error_all_mean"))
    assert len(ev.warnings) == 1 and "door states not scored" in ev.warnings[0] and "map.mcap" in ev.warnings[0]
    # A truth whose log's span covers only the run's later part (hAL: another launch whose sim time also starts near
    # 0; 0.56 rad scored for a 0.005 rad run, without a word): scored, with a warning naming the share outside.
    later = replace(truth, start_ns=int(stamps[20]), files={"log": "other_launch.mcap"})
    ev = evaluate_runs([run], DoorbatchConfig(), truth=later)
    assert len(ev.warnings) == 1 and "40 % of its updates lie outside" in ev.warnings[0]
    assert "other_launch.mcap" in ev.warnings[0]
    assert not evaluate_runs([run], DoorbatchConfig(), truth=truth).warnings  # the run's own truth: no word


def test_error_along_the_corridor_averages_runs_per_bin() -> None:
    stamps, ref = _straight(101)  # x from 0 to 5 m
    runs = [RunTables(f"s{k}", "l", "mcl", stamps, ref + np.array([0, 0.1 * (k + 1), 0]), reference=ReferenceTrajectory(
        stamps, ref), params={"seed": k}) for k in range(2)]
    ev = evaluate_runs(runs, load_config(overrides=["evaluate.along_x_bin_m=1.0"]))
    (curve,) = ev.along_corridor
    assert curve.runs == 2
    np.testing.assert_allclose(curve.x_m, [0.5, 1.5, 2.5, 3.5, 4.5, 5.5])
    np.testing.assert_allclose(curve.mean_error_m, 0.15)
    np.testing.assert_allclose(curve.std_error_m, 0.05)
    table = summary_table(ev)
    (row,) = table.rows  # seeds are averaged into one row
    assert row[0][3] == "2"
    assert row[1][table.value_columns.index("ape_trans_rmse")] == pytest.approx(0.15)


def _result(log: Path, stamps: np.ndarray, pose: np.ndarray, method: str, door_angle: float) -> LocalizationResult:
    u = len(stamps)
    return LocalizationResult(
        log=log.name, method=method, stamps_ns=stamps, pose=pose, cov=np.tile(np.eye(3) * 1e-3, (u, 1, 1)),
        odom=pose.copy(), n_particles=np.full(u, 500, np.int32), neff=np.full(u, 400.0),
        door_mean=np.full((u, 1), door_angle), door_std=np.full((u, 1), 0.05), door_observed=np.ones((u, 1), bool),
        particles=np.zeros((u, 1, 3)), converged_ns=int(stamps[0]))


def _write_run(folder: Path, log: Path, stamps: np.ndarray, pose: np.ndarray, method: str,
               door_angle: float, config: DoorbatchConfig | None = None) -> None:
    write_run_tables(folder, _result(log, stamps, pose, method, door_angle))
    manifest = Manifest.start((config or DoorbatchConfig()).as_dict(), [log], command="localize", method=method,
                              init="reference")
    manifest.extra.update({"converged_after_s": 0.0, "ambiguous": False, "lost_after_s": []})
    manifest.write(folder / "manifest.json")


def test_evaluate_cli_writes_the_report_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stamps, ref = _straight()
    log = tmp_path / "loc.mcap"
    log.write_bytes(b"not read")  # only its name and the reference beside it are used
    write_tum(tmp_path / "loc.truth.tum", stamps, *ref.T)
    _write_run(tmp_path / "runs" / "mcl", log, stamps, ref + np.array([0.0, 0.2, 0.0]), "mcl", 0.0)
    _write_run(tmp_path / "runs" / "rbpf", log, stamps, ref + np.array([0.0, 0.05, 0.0]), "rbpf", 0.3)
    out = tmp_path / "report"
    code = main(["evaluate", str(tmp_path / "runs" / "mcl"), str(tmp_path / "runs" / "rbpf"), "-o", str(out),
                 "--json"])
    assert code == 0

    def not_json(word: str) -> None:
        raise AssertionError(f"{word} is not JSON (JSON.parse, jq refuse it)")

    summary = json.loads(capsys.readouterr().out, parse_constant=not_json)
    assert summary["runs"] == 2
    never_lost = [r["value"] for r in summary["metrics"] if r["metric"] == "time_to_lost_s"]
    assert never_lost == [None, None]  # NaN in metrics.parquet: no number, null
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    rmse = {r: v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)
            if m == "ape_trans_rmse"}
    assert rmse == pytest.approx({"mcl": 0.2, "rbpf": 0.05})
    assert pq.read_schema(out / "metrics.parquet").names == ["run", "log", "method", "metric", "value", "unit",
                                                              "params"]
    page = (out / "report.html").read_text()
    png = base64.b64decode(page.split("data:image/png;base64,")[1].split('"')[0])
    assert png.startswith(b"\x89PNG") and "src=\"error_along_x.png\"" not in page  # embedded, not linked
    assert (out / "error_along_x.png").read_bytes()[:4] == b"\x89PNG"
    hashed = [Path(i["path"]).relative_to(tmp_path).as_posix() for i in Manifest.read(out / "manifest.json").inputs]
    assert {"runs/mcl/trajectory.parquet", "runs/mcl/door_states.parquet", "runs/rbpf/door_states.parquet"} <= set(
        hashed)  # door states are scored too
    assert "| loc.mcap | rbpf |" in (out / "report.md").read_text()
    again = tmp_path / "again"  # deterministic: the same inputs give the same bytes (reruns of doorbatch run)
    assert main(["evaluate", str(tmp_path / "runs" / "mcl"), str(tmp_path / "runs" / "rbpf"), "-o", str(again),
                 "-q"]) == 0
    for name in ("metrics.parquet", "report.md", "report.html", "error_along_x.png"):
        assert (again / name).read_bytes() == (out / name).read_bytes(), name
    twice = tmp_path / "twice"  # a run named twice (another spelling of its path) counts once
    assert main(["evaluate", str(tmp_path / "runs" / "mcl"), str(tmp_path / "runs" / ".." / "runs" / "mcl"),
                 str(tmp_path / "runs" / "rbpf"), "-o", str(twice), "-q"]) == 0
    assert (twice / "metrics.parquet").read_bytes() == (out / "metrics.parquet").read_bytes()


def test_another_localizers_tum_trajectory_is_scored_beside_a_run(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """AMCL's /amcl_pose exported as TUM (evo_traj) next to a doorbatch run, both against --reference: every 3rd
    stamp only (AMCL publishes on its updates), 0.1 m off along y."""
    stamps, ref = _straight()
    log = tmp_path / "loc.mcap"
    log.write_bytes(b"not read")
    write_tum(tmp_path / "reference.tum", stamps, *ref.T)
    _write_run(tmp_path / "rbpf", log, stamps, ref + np.array([0.0, 0.05, 0.0]), "rbpf", 0.3)
    write_tum(tmp_path / "amcl.tum", stamps[::3], *(ref[::3] + np.array([0.0, 0.1, 0.0])).T)
    out = tmp_path / "report"
    args = ["evaluate", str(tmp_path / "rbpf"), str(tmp_path / "amcl.tum"), "-o", str(out)]
    assert main([*args, "--reference", str(tmp_path / "reference.tum"), "-q"]) == 0
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    rmse = {r: v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)
            if m == "ape_trans_rmse"}
    assert rmse == pytest.approx({"rbpf": 0.05, "amcl": 0.1})
    told = {(r, m): v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)
            if m in ("converged", "time_to_converge_s", "ambiguous")}
    assert told[("rbpf", "converged")] == 1.0 and told[("rbpf", "ambiguous")] == 0.0
    # a TUM file says nothing of convergence: unknown, not "converged at its first pose, never ambiguous"
    assert all(math.isnan(told[("amcl", m)]) for m in ("converged", "time_to_converge_s", "ambiguous"))
    assert main(args) == 2  # a TUM file has no log beside which to find its reference
    assert "--reference" in capsys.readouterr().err
    # the same poses straight from a recorded session's /amcl_pose (LOG:/TOPIC), no export
    from doorbatch.io import ros_messages
    from doorbatch.io.log_writer import LogWriter

    session = tmp_path / "session.mcap"
    with LogWriter(session) as writer:
        for t, (x, y, yaw) in zip(stamps[::3], ref[::3], strict=True):
            writer.write("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", int(t),
                         ros_messages.pose_with_covariance_stamped(int(t), "map", x, y + 0.1, yaw, np.eye(6)))
    out2 = tmp_path / "report2"
    assert main(["evaluate", str(tmp_path / "rbpf"), f"{session}:/amcl_pose", "-o", str(out2), "--reference",
                 str(tmp_path / "reference.tum"), "-q"]) == 0
    table = read_table("metrics", out2 / "metrics.parquet").to_pydict()
    rmse = {m: v for m, k, v in zip(table["method"], table["metric"], table["value"], strict=True)
            if k == "ape_trans_rmse"}
    assert rmse == pytest.approx({"rbpf": 0.05, "amcl_pose": 0.1})
    assert main(["evaluate", f"{session}:/odom", "-o", str(out2), "--reference", str(tmp_path / "reference.tum")]) == 2
    assert "pose topics in the log: /amcl_pose" in capsys.readouterr().err


def test_a_log_without_a_laser_or_one_of_its_pose_topics_is_a_reference(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A motion-capture or ground-truth recording has poses but no laser: ``--reference LOG`` takes its reference
    pose topic (it was refused: "no sensor_msgs/LaserScan topic"), and ``--reference LOG:/TOPIC`` names the topic,
    as a run may (it was read as a file name that does not exist)."""
    from doorbatch.io import ros_messages
    from doorbatch.io.log_writer import LogWriter

    stamps, ref = _straight()
    log = tmp_path / "loc.mcap"
    log.write_bytes(b"not read")
    _write_run(tmp_path / "rbpf", log, stamps, ref + np.array([0.0, 0.05, 0.0]), "rbpf", 0.3)
    mocap = tmp_path / "mocap.mcap"
    with LogWriter(mocap) as writer:
        for t, (x, y, yaw) in zip(stamps, ref, strict=True):
            writer.write("/ground_truth", "geometry_msgs/msg/PoseStamped", int(t),
                         ros_messages.pose_stamped(int(t), "map", x, y, yaw))
            writer.write("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", int(t),
                         ros_messages.pose_with_covariance_stamped(int(t), "map", x, y + 0.02, yaw, np.eye(6)))
    for reference, want in ((str(mocap), 0.05), (f"{mocap}:/ground_truth", 0.05), (f"{mocap}:/amcl_pose", 0.03)):
        out = tmp_path / f"report_{want}_{len(reference)}"
        assert main(["evaluate", str(tmp_path / "rbpf"), "-o", str(out), "--reference", reference, "-q"]) == 0
        table = read_table("metrics", out / "metrics.parquet").to_pydict()
        rmse = [v for k, v in zip(table["metric"], table["value"], strict=True) if k == "ape_trans_rmse"]
        assert rmse == pytest.approx([want]), reference
    assert main(["evaluate", str(tmp_path / "rbpf"), "-o", str(tmp_path / "bad"), "--reference",
                 f"{mocap}:/odom"]) == 2
    assert "pose topics in the log: /amcl_pose, /ground_truth" in capsys.readouterr().err
    # a laserless log whose only pose is an Odometry named as wheel odometry is: no reference role; the error
    # names LOG:/TOPIC and the log's pose topics
    vicon = tmp_path / "vicon.mcap"
    with LogWriter(vicon) as writer:
        for t, (x, y, yaw) in zip(stamps, ref, strict=True):
            writer.write("/vicon/robot/odom", "nav_msgs/msg/Odometry", int(t),
                         ros_messages.odometry(int(t), "map", "base_link", x, y, yaw))
    code = main(["evaluate", str(tmp_path / "rbpf"), "-o", str(tmp_path / "bad"), "--reference", str(vicon)])
    err = capsys.readouterr().err
    assert code == 3 and "LOG:/TOPIC" in err and "/vicon/robot/odom" in err, err
    assert main(["evaluate", str(tmp_path / "rbpf"), "-o", str(tmp_path / "vicon"), "--reference",
                 f"{vicon}:/vicon/robot/odom", "-q"]) == 0


def test_evaluate_cli_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["evaluate", "-o", str(tmp_path / "r")]) == 2
    (tmp_path / "empty").mkdir()
    assert main(["evaluate", str(tmp_path / "empty"), "-o", str(tmp_path / "r")]) == 3
    assert "neither a run directory" in capsys.readouterr().err


def test_a_run_in_memory_scores_as_its_run_directory(tmp_path: Path) -> None:
    stamps, ref = _straight()
    log = tmp_path / "loc.mcap"
    log.write_bytes(b"")
    truth = _truth(0.5)
    map_doors = DoorSet(np.array([[5.0, 1.1]]), np.array([0.9]), np.zeros(1), np.zeros(1), np.ones(1))
    result = _result(log, stamps, ref + np.array([0.02, -0.03, 0.01]), "rbpf", 0.45)
    reference = ReferenceTrajectory(stamps, ref)
    _write_run(tmp_path / "run", log, stamps, result.pose, "rbpf", 0.45)
    from doorbatch.io.run_reader import read_run_dir

    on_disk = replace(read_run_dir(tmp_path / "run", DoorbatchConfig(), "r"), map_doors=map_doors)
    in_memory = run_tables_from_result(result, name="r", map_doors=map_doors)
    a = evaluate_runs([on_disk], DoorbatchConfig(), reference=reference, truth=truth)
    b = evaluate_runs([in_memory], DoorbatchConfig(), reference=reference, truth=truth)
    assert [r.metric for r in a.metrics] == [r.metric for r in b.metrics]
    np.testing.assert_allclose([r.value for r in a.metrics], [r.value for r in b.metrics], atol=1e-12)
    truth_angle = np.minimum(0.5, 0.005 * np.arange(200))  # the truth ramps 0 → 0.5 rad over 10 s, then stays
    assert a.value("r", "door_state_error_mean") == pytest.approx(np.mean(np.abs(0.45 - truth_angle)))


def _map_metrics(out: Path) -> dict[str, float]:
    """Metric → value of a report on one map."""
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    return dict(zip(table["metric"], table["value"], strict=True))


def _map_dir(folder: Path, doors: DoorSet, source: str = "grid", moved: list[bool] | None = None) -> Path:
    import shutil

    from doorbatch.io.parquet import write_table

    folder.mkdir(parents=True)
    for suffix in ("yaml", "pgm"):
        shutil.copy(SAMPLE_LOGS / f"map.map_static.{suffix}", folder / f"map.{suffix}")
    (folder / "map.yaml").write_text((folder / "map.yaml").read_text().replace("map.map_static.pgm", "map.pgm"))
    n = len(doors)
    write_table("doors", {"door_id": np.arange(n, dtype=np.int32), "hinge_x": doors.hinge[:, 0],
                          "hinge_y": doors.hinge[:, 1], "length": doors.length, "closed_yaw": doors.closed_yaw,
                          "angle_min": doors.angle_min, "angle_max": doors.angle_max,
                          "n_observations": np.full(n, 5, np.int32), "source": [source] * n,
                          "moved": [True] * n if moved is None else moved},
                folder / "doors.parquet")
    manifest = Manifest.start(DoorbatchConfig().as_dict(), [SAMPLE_LOGS / "map_pass1.mcap"], command="map")
    manifest.write(folder / "manifest.json")
    return folder


def test_door_maps_are_scored_against_the_mapping_truth(tmp_path: Path) -> None:
    from doorbatch.io.sim_truth import read_truth
    from doorbatch.pipeline.evaluate.door_map import truth_doors

    truth = read_truth(SAMPLE_LOGS / "map.truth.yaml")
    doors, moved = truth_doors(truth, math.radians(DoorbatchConfig().doors.min_opening_deg))
    keep = np.flatnonzero(moved)
    exact = DoorSet(doors.hinge[keep], doors.length[keep], doors.closed_yaw[keep], doors.angle_min[keep],
                    doors.angle_max[keep])
    shifted_hinge = exact.hinge.copy()
    shifted_hinge[0] += [0.5, 0.0]  # beyond the 0.3 m match radius: a false positive and a missed door
    shifted = DoorSet(shifted_hinge, exact.length + 0.05, exact.closed_yaw, exact.angle_min, exact.angle_max)
    out = tmp_path / "report"
    args = ["evaluate", str(_map_dir(tmp_path / "exact", exact)), str(_map_dir(tmp_path / "shifted", shifted)),
            "-o", str(out), "-q"]
    assert main(args) == 0  # the truth is found next to the map's logs (map.truth.yaml of the sample)
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    got = {(r, m): v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)}
    n = len(keep)
    assert got[("exact", "door_precision")] == 1.0 and got[("exact", "door_recall")] == 1.0
    assert got[("exact", "door_hinge_error_mean")] == pytest.approx(0.0, abs=1e-12)
    assert got[("shifted", "door_precision")] == pytest.approx((n - 1) / n)
    assert got[("shifted", "door_recall")] == pytest.approx((n - 1) / n)
    assert got[("shifted", "door_length_error_mean")] == pytest.approx(0.05)
    hashed = {Path(i["path"]).name for i in Manifest.read(out / "manifest.json").inputs}
    assert {"map.yaml", "map.pgm", "doors.parquet"} <= hashed  # DESIGN: each input file with its hash
    assert main([*args[:-1], "--world", str(SAMPLE_LOGS / "map.truth.yaml")]) == 0  # the same truth, given


def test_a_door_map_without_a_truth_counts_its_doors_and_says_why_no_more(tmp_path: Path) -> None:
    from doorbatch.pipeline.evaluate.report import MapTables

    doors = DoorSet(np.array([[1.0, 2.0], [4.0, 0.0]]), np.array([0.9, 0.8]), np.zeros(2), np.zeros(2), np.ones(2))
    ev = evaluate_runs([], DoorbatchConfig(), maps=[MapTables("own_robot", doors, None)])
    assert [(r.metric, r.value) for r in ev.metrics] == [("doors_detected", 2.0)]
    assert len(ev.warnings) == 1 and "--world" in ev.warnings[0]


def test_summary_rows_follow_the_particle_count_numerically() -> None:
    stamps, ref = _straight(50)
    runs = [RunTables(f"r{n}", "l", "mcl", stamps, ref, reference=ReferenceTrajectory(stamps, ref),
                      params={"particles": n, "seed": 0}) for n in (10000, 5000, 1000, 20000)]
    table = summary_table(evaluate_runs(runs, DoorbatchConfig()))
    assert [labels[2] for labels, _ in table.rows] == [f"particles={n}" for n in (1000, 5000, 10000, 20000)]


def test_runs_of_one_log_on_different_maps_or_starts_are_not_averaged_together() -> None:
    stamps, ref = _straight(50)
    reference = ReferenceTrajectory(stamps, ref)

    def run(name: str, dy: float, init: str, map_path: str) -> RunTables:
        return RunTables(name, "l", "mcl", stamps, ref + np.array([0.0, dy, 0.0]), init=init, reference=reference,
                         map_path=map_path)

    seeds = [run("a0", 0.1, "reference", "/m1/map.yaml"), run("a1", 0.3, "reference", "/m1/map.yaml")]
    table = summary_table(evaluate_runs(seeds, DoorbatchConfig()))
    assert [(labels[2], labels[3]) for labels, _ in table.rows] == [("", "2")]  # seeds of one setup: one row
    mixed = [*seeds, run("b", 1.0, "global", "/m1/map.yaml"), run("c", 2.0, "reference", "/m2/map.yaml")]
    # maps are named by their folders, not where they live: the labels below hold on any machine
    table = summary_table(evaluate_runs(mixed, DoorbatchConfig()))
    rmse = table.value_columns.index("ape_trans_rmse")
    rows = {labels[2]: (labels[3], values[rmse]) for labels, values in table.rows}
    assert rows == {"init=reference, map=m1": ("2", pytest.approx(0.2)),
                    "init=global, map=m1": ("1", pytest.approx(1.0)),
                    "init=reference, map=m2": ("1", pytest.approx(2.0))}
    twins = [run("d", 0.1, "reference", "/x/site_a/map/map.yaml"), run("e", 0.2, "reference", "/x/site_b/map/map.yaml")]
    table = summary_table(evaluate_runs(twins, DoorbatchConfig()))
    assert sorted(labels[2] for labels, _ in table.rows) == ["map=site_a/map", "map=site_b/map"]


def test_runs_made_with_different_configs_are_not_averaged_as_seeds(tmp_path: Path) -> None:
    """Three MCL runs of one log with one seed and three configs (the defaults, a Nav2 params file, another beam
    combination) were one row "mean over seeds": each is a row of its own now, named by the keys where it leaves
    the defaults; a run that differs from another only in its seed still averages with it."""
    from doorbatch.pipeline.evaluate.stage import evaluate_run_dirs

    stamps, ref = _straight()
    log = tmp_path / "normal.mcap"
    log.write_bytes(b"not read")
    write_tum(tmp_path / "normal.truth.tum", stamps, *ref.T)
    nav2 = [f"localize.alpha{i}=0.2" for i in range(1, 5)] + ["localize.z_hit=0.5", "localize.z_rand=0.5"]
    setups = {"normal_mcl_def": (DoorbatchConfig(), 0.005),
              "normal_mcl_def_s1": (load_config(overrides=["seed=1"]), 0.007),
              "normal_mcl_nav2": (load_config(overrides=nav2), 0.029),
              "normal_mcl_prob": (load_config(overrides=["localize.beam_combination=amcl"]), 0.112)}
    setups["normal_mcl_def_old"] = (load_config(overrides=["seed=2"]), 0.006)
    for name, (config, dy) in setups.items():
        _write_run(tmp_path / "runs" / name, log, stamps, ref + np.array([0.0, dy, 0.0]), "mcl", 0.0, config)
    # a run of an older doorbatch: its manifest lacks a key added since, which took its default then
    old = tmp_path / "runs" / "normal_mcl_def_old" / "manifest.json"
    manifest = json.loads(old.read_text())
    del manifest["config"]["localize"]["pose_estimate"]
    old.write_text(json.dumps(manifest))
    ev = evaluate_run_dirs([tmp_path / "runs" / n for n in setups], tmp_path / "report", DoorbatchConfig())
    params = {r.run: r.params for r in ev.metrics if r.metric == "ape_trans_rmse"}
    assert params["normal_mcl_def"] == params["normal_mcl_def_s1"] == params["normal_mcl_def_old"] == {
        "config": "default"}
    assert params["normal_mcl_prob"] == {"localize.beam_combination": "amcl"}
    # six keys leave the defaults: the first four, and a hash that keeps the label apart from any other config's
    assert {k: v for k, v in params["normal_mcl_nav2"].items() if k != "config"} == {
        "localize.alpha1": 0.2, "localize.alpha2": 0.2, "localize.alpha3": 0.2, "localize.alpha4": 0.2}
    assert params["normal_mcl_nav2"]["config"].endswith("(+2 keys)")
    table = summary_table(ev)
    rmse = table.value_columns.index("ape_trans_rmse")
    rows = {labels[2]: (labels[3], values[rmse]) for labels, values in table.rows}
    assert len(rows) == 3
    assert rows["config=default"] == ("3", pytest.approx(0.006))
    assert rows["localize.beam_combination=amcl"] == ("1", pytest.approx(0.112))
    stored = read_table("metrics", tmp_path / "report" / "metrics.parquet").to_pydict()
    assert json.loads(next(p for r, p in zip(stored["run"], stored["params"], strict=True)
                           if r == "normal_mcl_prob")) == {"localize.beam_combination": "amcl"}


def test_a_log_without_truth_files_gives_its_reference_topic(tmp_path: Path) -> None:
    from doorbatch.io.run_reader import read_run_dir
    from tests.conftest import sample_messages, write_messages

    log = write_messages(tmp_path / "real.mcap", sample_messages(n_scans=20))  # /ground_truth: (0.1 i + 1, ...)
    i = np.arange(20)
    stamps = T0 + 100_000_000 * (i + 1)
    truth = np.stack([0.1 * i + 1, 0.02 * i, 0.01 * i], axis=1)
    _write_run(tmp_path / "run", log, stamps, truth + np.array([0.0, 0.25, 0.0]), "mcl", 0.0)
    run = read_run_dir(tmp_path / "run", DoorbatchConfig())
    assert run.reference is not None and len(run.reference.stamps_ns) == 20
    ev = evaluate_runs([run], DoorbatchConfig())
    assert ev.value("run", "ape_trans_rmse") == pytest.approx(0.25, abs=1e-6)
    assert read_run_dir(tmp_path / "run", DoorbatchConfig(), find_reference=False).reference is None


def test_a_reference_that_is_the_odometry_again_gives_convergence_metrics_only(tmp_path: Path) -> None:
    """A raw CARMEN log's reference is its odometry moved rigidly: a run was scored against that odometry (APE RMSE
    7 m, global success 0 % for a run 2 cm off the truth) while a warning said there is no independent reference.
    Its own reference now gives convergence metrics only, and the warning says so; ``--reference`` is still used."""
    from tests.conftest import sample_messages, write_messages

    log = write_messages(tmp_path / "raw.mcap", sample_messages(n_scans=30))  # /ground_truth = /odom + (1, 0, 0)
    i = np.arange(30)
    stamps = T0 + 100_000_000 * (i + 1)
    truth = np.stack([0.1 * i + 1, 0.02 * i, 0.01 * i], axis=1)
    _write_run(tmp_path / "run", log, stamps, truth + np.array([0.0, 0.25, 0.0]), "mcl", 0.0)
    out = tmp_path / "report"
    assert main(["evaluate", str(tmp_path / "run"), "-o", str(out), "-q"]) == 0
    metrics = set(read_table("metrics", out / "metrics.parquet").to_pydict()["metric"])
    assert "converged" in metrics and not any(m.startswith(("ape_", "rpe_")) for m in metrics), metrics
    warnings = Manifest.read(out / "manifest.json").warnings
    assert any("no independent reference" in w and "APE, RPE and global success are not reported" in w
               for w in warnings), warnings
    given = tmp_path / "given"
    assert main(["evaluate", str(tmp_path / "run"), "-o", str(given), "--reference", str(log), "-q"]) == 0
    table = read_table("metrics", given / "metrics.parquet").to_pydict()
    rmse = [v for m, v in zip(table["metric"], table["value"], strict=True) if m == "ape_trans_rmse"]
    assert rmse == pytest.approx([0.25], abs=1e-6)
    again = ReferenceTrajectory(stamps, truth, independent=False)  # a global start: no success judged against it
    run = RunTables("g", "raw.mcap", "mcl", stamps, truth, init="global", converged_ns=int(stamps[0]), reference=again)
    ev = evaluate_runs([run], DoorbatchConfig())
    assert math.isnan(ev.value("g", "global_success")) and ev.value("g", "converged") == 1.0 and ev.warnings
    assert evaluate_runs([run], DoorbatchConfig(), reference=again).value("g", "global_success") == 1.0


def test_runs_of_one_log_read_its_reference_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An experiment has tens of runs per log: the log's reference (a whole log read) is read once for all."""
    import doorbatch.io.run_reader as run_reader
    from tests.conftest import sample_messages, write_messages

    log = write_messages(tmp_path / "real.mcap", sample_messages(n_scans=20))
    i = np.arange(20)
    stamps = T0 + 100_000_000 * (i + 1)
    truth = np.stack([0.1 * i + 1, 0.02 * i, 0.01 * i], axis=1)
    for k, offset in enumerate((0.25, 0.5)):
        _write_run(tmp_path / f"run{k}", log, stamps, truth + np.array([0.0, offset, 0.0]), "mcl", 0.0)
    reads: list[Path] = []
    real = run_reader.read_reference
    monkeypatch.setattr(run_reader, "read_reference", lambda path, config: reads.append(path) or real(path, config))
    runs = run_reader.read_run_dirs([tmp_path / "run0", tmp_path / "run1"], DoorbatchConfig(), ["a", "b"])
    assert reads == [log]
    ev = evaluate_runs(runs, DoorbatchConfig())
    assert ev.value("a", "ape_trans_rmse") == pytest.approx(0.25, abs=1e-6)
    assert ev.value("b", "ape_trans_rmse") == pytest.approx(0.5, abs=1e-6)


def test_em_door_maps_count_the_doors_that_never_moved(tmp_path: Path) -> None:
    """An em map (paper 001) also reports doors that never moved: they are true detections, not false
    positives, and recall is given for moved and never-moved doors apart."""
    from doorbatch.io.sim_truth import read_truth
    from doorbatch.pipeline.evaluate.door_map import truth_doors

    doors, moved = truth_doors(read_truth(SAMPLE_LOGS / "map.truth.yaml"),
                               math.radians(DoorbatchConfig().doors.min_opening_deg))
    assert moved.any() and (~moved).any()
    never = np.flatnonzero(~moved)
    keep = np.concatenate([np.flatnonzero(moved), never[:-1]])  # every moved door, all but one never-moved
    found = DoorSet(doors.hinge[keep], doors.length[keep], doors.closed_yaw[keep], doors.angle_min[keep],
                    doors.angle_max[keep])
    out = tmp_path / "report"
    assert main(["evaluate", str(_map_dir(tmp_path / "em", found, "em")), str(_map_dir(tmp_path / "grid", found)),
                 "-o", str(out), "-q"]) == 0
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    got = {(r, m): v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)}
    assert got[("em", "door_precision")] == 1.0
    assert got[("em", "door_recall_moved")] == 1.0
    assert got[("em", "door_recall_never_moved")] == pytest.approx((len(never) - 1) / len(never))
    assert got[("em", "door_recall")] == pytest.approx((len(keep)) / len(moved))
    assert got[("em", "doors_truth")] == len(moved)  # what recall counts: every door (it had said the moved ones)
    assert got[("grid", "doors_truth")] == moved.sum()
    # the same doors as a grid map: the never-moved ones are not what the grid stage may report
    assert got[("grid", "door_precision")] == pytest.approx(moved.sum() / len(keep))
    assert ("grid", "door_recall_never_moved") not in got


def test_an_em_door_that_never_moved_counts_at_either_end_of_its_leaf(tmp_path: Path) -> None:
    """An em stage's never-moved door seen closed shows no hinge: mapped at its free end (doors.parquet's moved
    false), it is the truth's door, not a false positive 0.9 m off (hAO: precision 0.5-0.8 on em_corridor)."""
    from doorbatch.io.sim_truth import read_truth
    from doorbatch.pipeline.evaluate.door_map import truth_doors
    from doorbatch.pipeline.localize.door_geometry import other_end

    doors, moved = truth_doors(read_truth(SAMPLE_LOGS / "map.truth.yaml"),
                               math.radians(DoorbatchConfig().doors.min_opening_deg))
    seen_closed = ~moved & (np.abs(doors.angle_min + doors.angle_max) / 2 <= math.radians(5.0))
    assert seen_closed.any()
    tip = other_end(doors)
    flip = seen_closed[:, None]
    mapped = DoorSet(np.where(flip, tip.hinge, doors.hinge), doors.length,
                     np.where(seen_closed, tip.closed_yaw, doors.closed_yaw),
                     np.where(seen_closed, 0.0, doors.angle_min), np.where(seen_closed, 0.0, doors.angle_max))
    out = tmp_path / "report"
    assert main(["evaluate", str(_map_dir(tmp_path / "em", mapped, "em", moved.tolist())), "-o", str(out), "-q"]) == 0
    table = read_table("metrics", out / "metrics.parquet").to_pydict()
    got = dict(zip(table["metric"], table["value"], strict=True))
    assert got["door_precision"] == 1.0 and got["door_recall"] == 1.0 and got["door_recall_never_moved"] == 1.0
    assert got["door_hinge_error_mean"] < 1e-6


def test_a_truth_without_leaf_observations_scores_doors_by_position(tmp_path: Path) -> None:
    """A hand-written truth lacked ``leaf_observations``: every truth door counted as never moved, and a map whose
    doors were all within 1 cm got precision 0, recall 1 and no hinge errors. Every truth door is now one the map
    should have, matched by position, and a warning says moved and never-moved recall cannot be told."""
    import yaml

    from doorbatch.io.sim_truth import read_truth

    doc = yaml.safe_load((SAMPLE_LOGS / "map.truth.yaml").read_text())
    del doc["leaf_observations"]
    doc["world"]["doors"] = doc["world"]["doors"][:3]
    doc["door_angles"]["rows"] = [r for r in doc["door_angles"]["rows"] if r[1] < 3]
    world = tmp_path / "truth.yaml"
    world.write_text(yaml.safe_dump(doc))
    truth = read_truth(world)
    hinge = np.array([[d.hinge_x + 0.01, d.hinge_y] for d in truth.doors])
    doors = DoorSet(hinge, np.array([d.length for d in truth.doors]), np.array([d.closed_yaw for d in truth.doors]),
                    np.zeros(3), np.full(3, 1.2))
    out = tmp_path / "report"
    assert main(["evaluate", str(_map_dir(tmp_path / "map", doors)), "--world", str(world), "-o", str(out), "-q"]) == 0
    got = _map_metrics(out)
    assert got["door_precision"] == 1.0 and got["door_recall"] == 1.0 and got["doors_truth"] == 3
    assert got["door_hinge_error_mean"] == pytest.approx(0.01)
    assert "door_recall_moved" not in got and "door_recall_never_moved" not in got
    warnings = Manifest.read(out / "manifest.json").warnings
    assert any("no leaf_observations" in w and "cannot be told" in w for w in warnings), warnings
    # not said is not "the laser saw no leaf" (an empty list), and is written back as not said
    assert truth.leaf_observations is None and "leaf_observations" not in truth.to_dict()
    for empty in ([], {"rows": []}):  # an empty list read as a mapping had raised AttributeError, a traceback
        doc["leaf_observations"] = empty
        world.write_text(yaml.safe_dump(doc))
        assert read_truth(world).leaf_observations == ()


def test_a_minimal_hand_written_truth_scores_a_map(tmp_path: Path) -> None:
    """A Stage user's truth: format, the doors' geometry (numbered from 1), door_angles and leaf_observations, no
    names, heights, colours, segments, generator or files. Each missing key had stopped evaluate with a bare
    ``KeyError: 'color_mean_rgb'`` (exit 3), one key per try; a leaf row of door 3 had indexed the third door. A
    missing required key is named."""
    import yaml

    doors = [{"door_id": k + 1, "hinge_x": 2.0 + 3.0 * k, "hinge_y": 1.0, "length": 0.9, "closed_yaw": 0.0,
              "opening_sign": 1, "max_angle": 1.6} for k in range(3)]
    doc = {"format": "doorbatch-sim-truth/1", "world": {"doors": doors},
           "door_angles": {"columns": ["stamp_ns", "door_id", "angle"],
                           "rows": [[0, k + 1, 0.0] for k in range(3)] + [[10**9, k + 1, 1.0] for k in range(3)]},
           "leaf_observations": {"rows": [[0, 3, 40, 12, 0.0, 1.0], [0, 1, 40, 12, 0.0, 0.0]]}}
    world = tmp_path / "hand.truth.yaml"
    world.write_text(yaml.safe_dump(doc))
    found = DoorSet(np.array([[8.01, 1.0]]), np.array([0.9]), np.array([0.0]), np.zeros(1), np.ones(1))
    out = tmp_path / "report"
    assert main(["evaluate", str(_map_dir(tmp_path / "map", found)), "--world", str(world), "-o", str(out), "-q"]) == 0
    got = _map_metrics(out)
    # only door 3 (id 3, the third) was seen at two angles: the one found is it
    assert got["doors_truth"] == 1 and got["door_precision"] == 1.0 and got["door_recall"] == 1.0
    assert got["door_hinge_error_mean"] == pytest.approx(0.01)
    del doc["world"]["doors"][1]["closed_yaw"]
    world.write_text(yaml.safe_dump(doc))
    assert main(["evaluate", str(tmp_path / "map"), "--world", str(world), "-o", str(tmp_path / "r2"), "-q"]) == 3


def test_passes_recorded_apart_with_a_truth_each_are_scored_against_all_of_them(tmp_path: Path) -> None:
    """Stage or Gazebo restarted per pass: each pass's log has its own truth, every clock starting at 0. The map
    had been scored against the first pass's truth alone (range error 1.25 rad, no warning); the truths are now
    merged onto one time line, each pass's angles its own."""
    import yaml

    from doorbatch.io.manifest import Manifest

    logs = []
    for k, angle in enumerate((0.0, 1.2)):
        log = tmp_path / "logs" / f"pass{k + 1}.bag"
        log.parent.mkdir(exist_ok=True)
        log.write_bytes(b"a log")
        doc = {"format": "doorbatch-sim-truth/1", "start_ns": 0, "end_ns": 10**10,
               "world": {"doors": [{"door_id": 0, "hinge_x": 3.0, "hinge_y": 1.0, "length": 0.9, "closed_yaw": 0.0,
                                    "opening_sign": 1, "max_angle": 1.6}]},
               "passes": [{"index": 0, "begin_ns": 0, "stationary_ns": 0, "end_ns": 10**10}],
               "door_angles": {"rows": [[0, 0, angle]]}}
        (log.parent / f"pass{k + 1}.truth.yaml").write_text(yaml.safe_dump(doc))
        logs.append(log)
    folder = _map_dir(tmp_path / "map", DoorSet(np.array([[3.0, 1.0]]), np.array([0.9]), np.zeros(1), np.zeros(1),
                                                np.full(1, 1.2)))
    Manifest.start(DoorbatchConfig().as_dict(), logs, command="map").write(folder / "manifest.json")
    out = tmp_path / "report"
    assert main(["evaluate", str(folder), "-o", str(out), "-q"]) == 0
    got = _map_metrics(out)
    assert got["door_precision"] == 1.0 and got["doors_truth"] == 1
    assert got["door_range_error_mean"] == pytest.approx(0.0, abs=1e-9)


def test_a_scan_matched_map_scored_against_a_world_frame_truth_is_told_why(tmp_path: Path) -> None:
    """A map built from scan-matched poses lies in its first pass's odometry frame, 1 m from the truth's world
    frame: precision 0, recall 0, and no word. A warning now names the frames; a reference map is not told."""
    from doorbatch.io.sim_truth import read_truth
    from doorbatch.pipeline.evaluate.door_map import truth_doors

    doors, moved = truth_doors(read_truth(SAMPLE_LOGS / "map.truth.yaml"),
                               math.radians(DoorbatchConfig().doors.min_opening_deg))
    shifted = DoorSet(doors.hinge[moved] + np.array([1.0, 0.0]), doors.length[moved], doors.closed_yaw[moved],
                      doors.angle_min[moved], doors.angle_max[moved])
    for source, told in (("scanmatch", True), ("reference", False)):
        folder = _map_dir(tmp_path / source, shifted)
        manifest = Manifest.read(folder / "manifest.json")
        manifest.extra["pose_source"] = source
        manifest.write(folder / "manifest.json")
        out = tmp_path / f"report_{source}"
        assert main(["evaluate", str(folder), "-o", str(out), "-q"]) == 0
        warnings = Manifest.read(out / "manifest.json").warnings
        assert any("first pass's odometry frame" in w and "precision 0.00" in w for w in warnings) == told, warnings
