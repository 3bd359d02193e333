"""doorbatch localize end to end on the sample: outputs, tracking against truth, determinism, errors."""

from __future__ import annotations

import json
import math
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, LocalizeConfig
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.parquet import read_table
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.run import load_localization_map
from tests.conftest import REPO

SAMPLE_LOGS = REPO / "datasets" / "sample" / "logs"


@pytest.fixture(scope="module")
def sample_map(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("map") / "map"
    logs = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]
    assert main(["map", *logs, "-o", str(out), "--stages", "grid", "-q"]) == 0
    return out


def _errors(run: Path, log: Path) -> np.ndarray:
    traj = read_table("trajectory", run / "trajectory.parquet").to_pydict()
    rec = load_recording(log, DoorbatchConfig())
    assert rec.reference is not None
    ref, _ = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, np.asarray(traj["stamp_ns"]))
    return np.asarray(np.hypot(np.asarray(traj["x"]) - ref[:, 0], np.asarray(traj["y"]) - ref[:, 1]))


@pytest.mark.parametrize("method", ["rbpf", "mcl"])
def test_localize_tracks_the_open_doors_log(sample_map: Path, tmp_path: Path, method: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    log = SAMPLE_LOGS / "loc_open.mcap"
    run = tmp_path / method
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", method, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["method"] == method and summary["updates"] > 100
    for name in ("trajectory.parquet", "door_states.parquet", "trajectory.tum", "annotated.mcap", "manifest.json"):
        assert (run / name).exists(), name
    err = _errors(run, log)
    assert err.mean() < 0.1, err.mean()
    states = read_table("door_states", run / "door_states.parquet").to_pydict()
    n_doors = len(read_table("doors", sample_map / "doors.parquet"))
    if method == "mcl":
        assert not states["door_id"]
        return
    # a row per door at every update, and at every scan the robot stood still (door_update_when_still: the sample
    # robot waits 1.7 s at the start), in time order
    stamps = np.asarray(states["stamp_ns"])
    updates = set(read_table("trajectory", run / "trajectory.parquet").to_pydict()["stamp_ns"])
    assert len(updates) == summary["updates"] and updates <= set(stamps.tolist())
    assert np.all(np.diff(stamps) >= 0) and len(stamps) % n_doors == 0 and len(stamps) > summary["updates"] * n_doors
    # a door flagged observed took a measurement: its estimate is no longer the prior's width (any particle's
    # match flagged a door at its prior, mid-range ± 30°, at the first update; door_observed_min_share)
    observed = np.asarray(states["observed"])
    assert observed.any()
    prior_rad = math.radians(LocalizeConfig().door_init_sigma_deg)
    assert np.all(np.asarray(states["angle_std"])[observed] < 0.9 * prior_rad)


@pytest.mark.parametrize(("method", "init"), [("rbpf", "reference"), ("mcl", "global")])
def test_same_seed_same_outputs(sample_map: Path, tmp_path: Path, method: str, init: str) -> None:
    # global: the smoothed, tempered, jittered phase too (2,000 particles to keep it short)
    log = str(SAMPLE_LOGS / "loc_partial.mcap")
    sets = ["--set", "localize.global_particles=2000", "--set", "localize.max_particles=2000"]
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        assert main(["localize", log, "--map", str(sample_map), "-o", str(tmp_path / name), "--method", method,
                     "--init", init, *sets, "--set", f"seed={seed}", "-q"]) == 0
    for name in ("trajectory.parquet", "door_states.parquet", "trajectory.tum"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes(), name
    # and the seed is what decides: another one gives another trajectory
    assert (tmp_path / "a" / "trajectory.tum").read_bytes() != (tmp_path / "c" / "trajectory.tum").read_bytes()


@pytest.mark.parametrize("relocalize", [False, True])
def test_a_global_run_that_is_lost_claims_nothing(sample_map: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 relocalize: bool) -> None:
    """Lost (criterion 4 of pipeline/localize/convergence.py) made certain: no scan fits the map. Once the cloud
    has been tight for lost_after_s the run says so; by default the same cloud goes on and claims nothing again,
    with relocalize_when_lost it is spread over the free space again (and again, as it settles); nothing is
    claimed either way."""
    from doorbatch.pipeline.localize import run as run_module

    monkeypatch.setattr(run_module, "scan_fit", lambda *_: 0.0)
    run = tmp_path / "lost"
    sets = ["localize.global_particles=2000", "localize.max_particles=2000", "localize.lost_after_s=5.0",
            f"localize.relocalize_when_lost={str(relocalize).lower()}"]
    assert main(["localize", str(SAMPLE_LOGS / "loc_partial.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--init", "global", *(a for s in sets for a in ("--set", s)), "-q"]) == 0
    manifest = json.loads((run / "manifest.json").read_text())
    lost = [w for w in manifest["warnings"] if w.startswith("lost at ")]
    times = np.array(manifest["extra"]["lost_after_s"])
    assert len(times) >= 1 and times[0] < 15.0 and np.all(np.diff(times) >= 5.0)
    assert len(lost) == 1 and lost[0].endswith("spread over the free space again") == relocalize
    assert float(lost[0].split()[2]) == pytest.approx(times[0], abs=0.05)
    again = [w for w in manifest["warnings"] if w.startswith("lost again at ")]
    assert len(again) == (len(times) > 1) and (relocalize or len(times) == 1)  # without: the fit never comes back
    assert manifest["extra"]["converged_after_s"] is None


def test_a_global_claim_lost_once_is_not_made_again_by_the_same_cloud(sample_map: Path, tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    from doorbatch.pipeline.localize import run as run_module

    def manifest(name: str, fit: Callable[..., float]) -> dict[str, Any]:
        monkeypatch.setattr(run_module, "scan_fit", fit)
        assert main(["localize", str(SAMPLE_LOGS / "loc_partial.mcap"), "--map", str(sample_map), "-o",
                     str(tmp_path / name), "--method", "mcl", "--init", "global", "--set",
                     "localize.global_particles=2000", "--set", "localize.max_particles=2000", "-q"]) == 0
        return dict(json.loads((tmp_path / name / "manifest.json").read_text()))

    assert manifest("fitting", lambda *_: 0.9)["extra"]["converged_after_s"] is not None  # it claims, and keeps it
    fits = iter([0.9] * 100 + [0.1] * 30 + [0.9] * 10_000)  # fitting, then not for 3 s (lost), then again
    lost = manifest("lost", lambda *_: next(fits))
    assert len([w for w in lost["warnings"] if w.startswith("lost at ")]) == 1
    assert lost["extra"]["converged_after_s"] is None


def test_a_lost_run_whose_estimate_is_off_the_map_says_where_it_is(sample_map: Path, tmp_path: Path) -> None:
    """An outside tester's estimates drove 21 m off their map and the lost warning did not say so: a start 7 m south
    of the corridor, beyond its wall, is lost there, and the warning names the estimate off the free space."""
    run = tmp_path / "off"
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--init", "20,-7,0", "-q"]) == 0
    manifest = json.loads((run / "manifest.json").read_text())
    lost = [w for w in manifest["warnings"] if w.startswith("lost at ")]
    assert len(lost) == 1 and "lies off the map's free space" in lost[0], manifest["warnings"]


def test_the_summary_of_a_lost_run_says_when_it_was_lost(sample_map: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """A tracked run is converged from its start, so ``--json`` said ``converged: true`` and nothing else of a run
    that was lost (an outside tester's cron job counted it good): the summary carries the lost episodes."""
    from doorbatch.pipeline.localize import run as run_module

    fits = iter([0.9] * 50 + [0.1] * 60 + [0.9] * 10_000)  # 5 s fitting, 6 s not, then fitting again
    monkeypatch.setattr(run_module, "scan_fit", lambda *_: next(fits))
    args = ["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "--method", "mcl"]
    assert main([*args, "-o", str(tmp_path / "json"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    manifest = json.loads((tmp_path / "json" / "manifest.json").read_text())
    assert summary["converged"] and len(summary["lost_after_s"]) == 1
    assert summary["lost_after_s"] == manifest["extra"]["lost_after_s"]
    assert summary["warnings"] == len(manifest["warnings"]) >= 1
    fits = iter([0.9] * 50 + [0.1] * 60 + [0.9] * 10_000)
    assert main([*args, "-o", str(tmp_path / "line")]) == 0
    assert f", lost at {summary['lost_after_s'][0]:.1f} s →" in capsys.readouterr().out


def test_a_tracked_run_that_is_lost_says_so_once_and_goes_on(sample_map: Path, tmp_path: Path,
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    from doorbatch.pipeline.localize import run as run_module

    fits = iter([0.9] * 50 + [0.1] * 60 + [0.9] * 10_000)  # 5 s fitting, 6 s not, then fitting again
    monkeypatch.setattr(run_module, "scan_fit", lambda *_: next(fits))
    run = tmp_path / "lost"
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--set", "localize.relocalize_when_lost=true", "-q"]) == 0
    manifest = json.loads((run / "manifest.json").read_text())
    lost = [w for w in manifest["warnings"] if w.startswith("lost at ")]
    assert len(lost) == 1 and "spread" not in lost[0]
    assert "beams end short of them" in lost[0]  # only the (patched) hits fit poorly: no beam passes a wall
    assert "off the map's free space" not in lost[0]  # the estimate is in the corridor
    assert any(w.startswith("localize.relocalize_when_lost spreads a lost cloud again only with --init global")
               for w in manifest["warnings"])  # set, and a tracked run cannot use it
    assert manifest["extra"]["converged_after_s"] == 0.0
    assert _errors(run, SAMPLE_LOGS / "loc_open.mcap").mean() < 0.1  # nothing else changed


@pytest.mark.parametrize("device", ["cpu", "cuda"])
def test_the_torch_backend_gives_numpys_outputs(sample_map: Path, tmp_path: Path, device: str) -> None:
    torch = pytest.importorskip("torch")
    if device == "cuda" and not torch.cuda.is_available():
        pytest.skip("no CUDA")
    log = str(SAMPLE_LOGS / "loc_partial.mcap")
    for method in ("rbpf", "mcl"):
        for backend in ("numpy", "torch"):
            assert main(["localize", log, "--map", str(sample_map), "-o", str(tmp_path / method / backend),
                         "--method", method, "--set", f"localize.backend={backend}", "--set",
                         f"localize.torch_device={device}", "-q"]) == 0
    # Both weigh a tracked cloud wholly on the device (beam skipping there, and the RBPF's door terms:
    # test_torch_field, test_torch_door_likelihood): exp, erf and the sums round otherwise, so a low-variance pick
    # may flip and the two runs differ by the filter's own sampling noise
    for method in ("rbpf", "mcl"):
        numpy_err, torch_err = (_errors(tmp_path / method / b, Path(log)) for b in ("numpy", "torch"))
        assert numpy_err.shape == torch_err.shape
        assert abs(numpy_err.mean() - torch_err.mean()) < 0.01 and abs(numpy_err.max() - torch_err.max()) < 0.05
    states = [read_table("door_states", tmp_path / "rbpf" / b / "door_states.parquet").to_pydict()
              for b in ("numpy", "torch")]
    assert states[0]["door_id"] == states[1]["door_id"] and len(states[0]["door_id"]) > 0
    angles = np.asarray(states[0]["angle"]) - np.asarray(states[1]["angle"])
    assert np.median(np.abs(angles)) < math.radians(1.0)


def test_a_nav2_params_file_runs_mcl_as_amcl_would(sample_map: Path, tmp_path: Path) -> None:
    """A user's nav2_params.yaml as --config: MCL takes its amcl node (what it leaves out at nav2_amcl's defaults:
    pf_err 0.05, z_hit 0.5, update_min_d 0.25, AMCL's likelihood_field) and tracks the sample."""
    params = tmp_path / "nav2_params.yaml"
    params.write_text("amcl:\n  ros__parameters:\n    base_frame_id: base_link\n    alpha1: 0.015\n"
                      "    alpha2: 0.0025\n    alpha3: 0.015\n    alpha4: 0.0005\n    max_particles: 1000\n"
                      "bt_navigator:\n  ros__parameters:\n    global_frame: map\n")
    log = SAMPLE_LOGS / "loc_open.mcap"
    run = tmp_path / "amcl"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl",
                 "--config", str(params), "-q"]) == 0
    lc = json.loads((run / "manifest.json").read_text())["config"]["localize"]
    assert (lc["max_particles"], lc["pf_err"], lc["z_hit"], lc["update_min_d"]) == (1000, 0.05, 0.5, 0.25)
    assert lc["beam_combination"] == "amcl" and lc["do_beamskip"] is False and lc["resample_neff_ratio"] == 1.0
    assert _errors(run, log).mean() < 0.2  # tracks (0.07-0.09 m over seeds 0-2; doorbatch's defaults 0.02 m)



def test_a_ros1_amcl_launch_file_runs_mcl_as_ros1_amcl_would(sample_map: Path, tmp_path: Path) -> None:
    """A ROS 1 robot's amcl.launch as --config: its parameters under ROS 1 names, ROS 1 amcl's defaults for the
    rest (laser_max_beams 30, kld_err 0.01, resample_interval 2), and the uncorrected ``diff`` odometry model. MCL
    tracks the sample with AMCL's stock alphas."""
    launch = tmp_path / "amcl.launch"
    launch.write_text("""<launch>
  <arg name="scan" default="/scan"/>
  <node pkg="amcl" type="amcl" name="amcl">
    <remap from="scan" to="$(arg scan)"/>
    <param name="odom_model_type" value="diff"/>
    <param name="max_particles" value="1000"/>
    <param name="laser_z_rand" value="0.2"/>
  </node>
</launch>
""")
    log = SAMPLE_LOGS / "loc_open.mcap"
    run = tmp_path / "ros1_amcl"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl",
                 "--config", str(launch), "-q"]) == 0
    manifest = json.loads((run / "manifest.json").read_text())["config"]
    lc = manifest["localize"]
    assert (lc["max_particles"], lc["max_beams"], lc["pf_err"], lc["resample_interval"]) == (1000, 30, 0.01, 2)
    assert lc["alpha_sums_as_std"] is True and lc["z_hit"] == 0.95 and lc["z_rand"] == 0.2
    assert manifest["topics"]["scan"] is None  # the node's scan is /scan: the log's own scan topic
    assert _errors(run, log).mean() < 0.3  # tracks (doorbatch's defaults 0.02 m; lost would be metres)

def _with_initial_pose(tmp_path: Path, after_scans: int, clock_offset_ns: int | None = 0
                       ) -> tuple[Path, int, np.ndarray]:
    """loc_open.mcap plus an RViz-style /initialpose (0.5 m, 15 deg std) at the reference pose of a later scan,
    0.2 m off it, recorded at that scan's time and stamped ``clock_offset_ns`` later (None: stamp 0, unset, as
    ``rostopic pub`` leaves it); returns the log, the scan's stamp and the reference pose there."""
    log, ((stamp, truth),) = _with_initial_poses(tmp_path, [(after_scans, 0.2)], clock_offset_ns)
    return log, stamp, truth


def _with_initial_poses(tmp_path: Path, poses: list[tuple[int, float]], clock_offset_ns: int | None = 0
                        ) -> tuple[Path, list[tuple[int, np.ndarray]]]:
    """loc_open.mcap plus one /initialpose per (scan index, metres off the reference along x) of ``poses``, in
    order (see :func:`_with_initial_pose`); returns the log and each scan's stamp and reference pose."""
    from doorbatch.io import ros_messages
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.reader import open_log

    src = SAMPLE_LOGS / "loc_open.mcap"
    rec = load_recording(src, DoorbatchConfig())
    assert rec.reference is not None
    cov = np.diag([0.25, 0.25, 0.0, 0.0, 0.0, 0.0685])
    pending, given = [], []
    for after_scans, off_m in poses:
        stamp = int(rec.scans.stamps_ns[after_scans])
        (truth,), _ = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, np.array([stamp]))
        msg = ros_messages.pose_with_covariance_stamped(0 if clock_offset_ns is None else stamp + clock_offset_ns,
                                                        "map", truth[0] + off_m, truth[1], truth[2], cov)
        pending.append((stamp, msg))
        given.append((stamp, truth))
    log = tmp_path / "with_initialpose.mcap"
    with open_log(src) as reader, LogWriter(log) as writer:
        for raw in reader.raw_messages():
            while pending and raw.log_time_ns > pending[0][0]:
                writer.write("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", *pending.pop(0))
            writer.write(raw.topic, raw.msgtype, raw.log_time_ns, raw.msg, raw.store)
    return log, given


def test_every_later_initialpose_starts_the_filter_anew(sample_map: Path, tmp_path: Path) -> None:
    """An operator who set the pose 3 m off and set it again 11 s later (as after a kidnapping): AMCL re-initializes
    on every /initialpose. Before, only the first was used and the run stayed metres off to the end, silently."""
    log, ((first, _), (second, _)) = _with_initial_poses(tmp_path, [(40, 3.0), (200, 0.2)])
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl",
                 "--init", "/initialpose", "-q"]) == 0
    stamps = np.asarray(read_table("trajectory", run / "trajectory.parquet").to_pydict()["stamp_ns"])
    err = _errors(run, log)
    assert stamps[0] == first and second in stamps
    before, after = err[stamps < second], err[stamps >= second]
    assert before.mean() > 1.0  # the wrong start holds along the corridor
    assert after[len(after) // 2:].mean() < 0.1
    warnings = json.loads((run / "manifest.json").read_text())["warnings"]
    assert sum("started anew" in w for w in warnings) == 1


@pytest.mark.parametrize("clock_offset_ns", [0, 100_000 * 10**9, None])  # another clock: a day later; unset
def test_init_from_the_logs_initialpose_starts_there_and_then(sample_map: Path, tmp_path: Path,
                                                              clock_offset_ns: int | None) -> None:
    """As Nav2 AMCL: the first /initialpose is the start, with its covariance, and scans before it are not used.
    RViz may stamp it with wall time while the scans carry sim time: then its log time says when. So does an
    unset stamp (0), which had started the run at the first scan, metres from the pose given for 4 s later."""
    log, stamp, _ = _with_initial_pose(tmp_path, 40, clock_offset_ns)
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl",
                 "--init", "/initialpose", "-q"]) == 0
    traj = read_table("trajectory", run / "trajectory.parquet").to_pydict()
    assert min(traj["stamp_ns"]) == stamp  # the scan at the message's stamp is the first update
    err = _errors(run, log)
    assert err[:3].mean() > 0.05  # the start is the operator's guess: 0.2 m off, half a metre of spread
    assert err[len(err) // 2:].mean() < 0.1  # and the scans pull it in
    manifest = json.loads((run / "manifest.json").read_text())
    assert manifest["extra"]["init"] == "/initialpose"
    assert any("another clock" in w for w in manifest["warnings"]) == bool(clock_offset_ns)
    assert any("unset (0)" in w for w in manifest["warnings"]) == (clock_offset_ns is None)


def test_init_from_a_topic_the_log_lacks_is_a_usage_error(sample_map: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(tmp_path / "r"),
                 "--init", "/initialpose"])
    err = capsys.readouterr().err
    assert code == 2 and "/initialpose" in err and "/ground_truth" in err  # names the pose topics it has
    code = main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(tmp_path / "r"),
                 "--init", "/scan"])
    assert code == 2 and "not a pose" in capsys.readouterr().err


def test_runs_on_a_plain_map_server_map_without_doors(sample_map: Path, tmp_path: Path) -> None:
    plain = tmp_path / "plain"
    plain.mkdir()
    shutil.copy(sample_map / "map.yaml", plain / "map.yaml")
    shutil.copy(sample_map / "map.pgm", plain / "map.pgm")
    run = tmp_path / "run"
    code = main(["localize", str(SAMPLE_LOGS / "loc_closed.mcap"), "--map", str(plain / "map.yaml"), "-o", str(run),
                 "--method", "mcl", "-q"])
    assert code == 0
    assert len(read_table("trajectory", run / "trajectory.parquet")) > 100
    assert not any("without doors" in w for w in json.loads((run / "manifest.json").read_text())["warnings"])
    rbpf = tmp_path / "rbpf"  # the RBPF on a map without doors says it has none to estimate
    assert main(["localize", str(SAMPLE_LOGS / "loc_closed.mcap"), "--map", str(plain / "map.yaml"), "-o", str(rbpf),
                 "--method", "rbpf", "-q"]) == 0
    assert any("without doors" in w for w in json.loads((rbpf / "manifest.json").read_text())["warnings"])


def test_a_map_recorded_in_a_log_localizes_as_its_yaml(sample_map: Path, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    """--map BAG: the last nav_msgs/OccupancyGrid on /map (a SLAM node's growing map: an earlier, smaller one
    first; a costmap topic beside it) is the map: the YAML's cells, its resolution to float32 (MapMetaData's
    type), and a run on it tracks."""
    from doorbatch.io import ros_messages
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.map_server import read_map

    occ = read_map(sample_map / "map.yaml")
    grid = "nav_msgs/msg/OccupancyGrid"
    log = tmp_path / "nav2_session.mcap"
    with LogWriter(log) as writer:
        early = np.full((20, 30), -1, dtype=np.int8)
        writer.write("/map", grid, 1, ros_messages.occupancy_grid(1, "map", early, 0.05, 0.0, 0.0))
        writer.write("/global_costmap/costmap", grid, 2, ros_messages.occupancy_grid(2, "map", early, 0.05, 0.0, 0.0))
        writer.write("/map", grid, 3, ros_messages.occupancy_grid(3, "map", occ.occupancy, occ.resolution_m,
                                                                  occ.origin_x_m, occ.origin_y_m, occ.origin_yaw_rad))
    recorded = load_localization_map(log, LocalizeConfig()).occupancy
    np.testing.assert_array_equal(recorded.occupancy, occ.occupancy)
    assert recorded.resolution_m == pytest.approx(occ.resolution_m, rel=1e-7)
    assert (recorded.origin_x_m, recorded.origin_y_m, recorded.origin_yaw_rad) == (
        occ.origin_x_m, occ.origin_y_m, occ.origin_yaw_rad)
    closed = SAMPLE_LOGS / "loc_closed.mcap"
    assert main(["localize", str(closed), "--map", str(log), "-o", str(tmp_path / "run"), "--method", "mcl",
                 "-q"]) == 0
    assert _errors(tmp_path / "run", closed).mean() < 0.1
    code = main(["localize", str(closed), "--map", str(closed), "-o", str(tmp_path / "none"), "--method", "mcl"])
    assert code == 2 and "OccupancyGrid topics in the log: none" in capsys.readouterr().err


def test_a_log_without_odometry_moves_by_its_matched_scans(sample_map: Path, tmp_path: Path) -> None:
    """No /odom and no odom → base_link in /tf (a robot without wheel encoders): the scans matched at constant
    velocity are the motion input (laser odometry), with a warning, and the filter tracks."""
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.reader import open_log

    src = SAMPLE_LOGS / "loc_open.mcap"
    log = tmp_path / "no_odometry.mcap"
    with open_log(src) as reader, LogWriter(log) as writer:
        for raw in reader.raw_messages():
            if raw.topic not in ("/odom", "/tf"):
                writer.write(raw.topic, raw.msgtype, raw.log_time_ns, raw.msg, raw.store)
    assert load_recording(log, DoorbatchConfig()).odometry is None
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl", "-q"]) == 0
    assert any("laser odometry" in w for w in json.loads((run / "manifest.json").read_text())["warnings"])
    assert _errors(run, log).mean() < 0.1


@pytest.mark.parametrize("init", ["1,2", "nan,0,0", "0,inf,0", "1e9,0,0"])
def test_bad_init_is_a_usage_error(sample_map: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                   init: str) -> None:
    """Not a pose, not finite, or off the map (1 km east): one line, exit 2, nothing written."""
    code = main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(tmp_path / "r"),
                 "--init", init])
    err = capsys.readouterr().err
    assert code == 2 and "--init" in err and "internal error" not in err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("particles", ["0", "-5"])
def test_a_particle_count_below_one_is_a_usage_error(sample_map: Path, tmp_path: Path, particles: str,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(tmp_path / "r"),
                 "--particles", particles])
    assert code == 2 and "--particles" in capsys.readouterr().err


@pytest.mark.parametrize("yaml_name", ["map.yaml", "office.yaml"])
def test_the_map_yaml_of_a_map_directory_keeps_its_doors(sample_map: Path, tmp_path: Path, yaml_name: str) -> None:
    """The map YAML named directly keeps the doors.parquet beside it, also renamed (a user's office.yaml, whose
    doors had been dropped with a warning that there were none)."""
    folder = tmp_path / "map"
    shutil.copytree(sample_map, folder)
    (folder / "map.yaml").rename(folder / yaml_name)
    run = tmp_path / "run"
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(folder / yaml_name), "-o",
                 str(run), "--method", "rbpf", "-q"]) == 0
    states = read_table("door_states", run / "door_states.parquet")
    assert len(states) > 0 and set(states.column("door_id").to_pylist()) == set(
        read_table("doors", sample_map / "doors.parquet").column("door_id").to_pylist())
    inputs = [Path(i["path"]).name for i in json.loads((run / "manifest.json").read_text())["inputs"]]
    assert inputs == ["loc_open.mcap", yaml_name, "doors.parquet"]  # every file the run used
    # and evaluate scores its door states against those doors (a renamed YAML had lost them there: a reviewer)
    assert main(["evaluate", str(run), "--world", str(SAMPLE_LOGS / "loc_open.truth.yaml"), "-o",
                 str(tmp_path / "eval"), "-q"]) == 0
    assert "door_state_error_mean" in read_table("metrics", tmp_path / "eval" / "metrics.parquet").column(
        "metric").to_pylist()


def test_a_folder_without_map_yaml_is_named_as_such(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "not_a_map").mkdir()
    code = main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(tmp_path / "not_a_map"), "-o",
                 str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2 and "no map.yaml" in err


def test_a_run_made_with_relative_paths_evaluates_from_any_folder(sample_map: Path, tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    work, elsewhere = tmp_path / "work", tmp_path / "else" / "where"  # another depth: ../ leads elsewhere
    work.mkdir()
    elsewhere.mkdir(parents=True)
    monkeypatch.chdir(work)
    log = os.path.relpath(SAMPLE_LOGS / "loc_open.mcap", work)
    assert main(["localize", log, "--map", os.path.relpath(sample_map, work), "-o", "run", "--method", "mcl",
                 "-q"]) == 0
    monkeypatch.chdir(elsewhere)
    assert main(["evaluate", str(work / "run"), "-o", "report", "-q"]) == 0
    metrics = set(read_table("metrics", elsewhere / "report" / "metrics.parquet").column("metric").to_pylist())
    assert "ape_trans_rmse" in metrics  # the reference was found beside the log the manifest names
    stages = json.loads((work / "run" / "manifest.json").read_text())["stage_seconds"]
    assert set(stages) == {"map", "localize", "write"} and all(math.isfinite(v) and v >= 0 for v in stages.values())
    assert set(json.loads((elsewhere / "report" / "manifest.json").read_text())["stage_seconds"]) == {"metrics",
                                                                                                    "report"}


def _stamps_shifted(msg: Any, shift_ns: int) -> None:
    """Every header stamp of ``msg`` (and of a TFMessage's transforms) moved by ``shift_ns``, in place."""
    headers = [t.header for t in getattr(msg, "transforms", [])] + ([msg.header] if hasattr(msg, "header") else [])
    for header in headers:
        ns = header.stamp.sec * 10**9 + header.stamp.nanosec + shift_ns
        header.stamp = type(header.stamp)(sec=ns // 10**9, nanosec=ns % 10**9)


def test_a_sim_time_log_gets_its_annotations_on_the_recorders_clock(sample_map: Path, tmp_path: Path) -> None:
    """Header stamps in sim time (from 0.5 s), log times on the recorder's wall clock, as `ros2 bag record` of a
    Gazebo run writes them: the annotations keep the stamps in their headers and are logged beside the scans
    they come from (before: at 0.5 s, 56 years before the input's messages on the file's timeline)."""
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.reader import open_log

    src = SAMPLE_LOGS / "loc_open.mcap"
    first_scan = int(load_recording(src, DoorbatchConfig()).scans.stamps_ns[0])
    shift = 500_000_000 - first_scan
    log = tmp_path / "sim_time.mcap"
    with open_log(src) as reader, LogWriter(log) as writer:
        for raw in reader.raw_messages():
            _stamps_shifted(raw.msg, shift)
            writer.write(raw.topic, raw.msgtype, raw.log_time_ns, raw.msg, raw.store)
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl", "-q"]) == 0
    traj = read_table("trajectory", run / "trajectory.parquet").to_pydict()
    assert min(traj["stamp_ns"]) < 10**10  # the trajectory is in the stamps' (sim) time
    assert _errors(run, log).mean() < 0.1
    with open_log(log) as reader:
        span = (reader.start_ns, reader.end_ns)
    with open_log(run / "annotated.mcap") as reader:
        added = [(raw.log_time_ns, raw.msg) for raw in reader.raw_messages(["/doorbatch/pose"])]
    assert added and all(span[0] <= t <= span[1] for t, _ in added)
    stamp = added[0][1].header.stamp
    assert stamp.sec * 10**9 + stamp.nanosec == min(traj["stamp_ns"])  # the header keeps the scan's stamp


def test_a_start_in_unknown_space_is_warned_and_the_lost_run_is_scored_lost(sample_map: Path, tmp_path: Path) -> None:
    """--init X,Y,YAW in a cell the map has never seen: a warning; the run then finds its scans do not fit and
    says so, and evaluate's metrics carry it (before: converged 1, time_to_converge 0, nothing about the loss)."""
    occ = load_localization_map(sample_map, LocalizeConfig()).occupancy
    i, j = (int(v[0]) for v in np.nonzero(occ.occupancy < 0))
    x, y = occ.cell_to_world([[i, j]])[0]
    log = SAMPLE_LOGS / "loc_open.mcap"
    runs = {"lost": ["--init", f"{x},{y},0"], "tracked": []}
    for name, extra in runs.items():
        assert main(["localize", str(log), "--map", str(sample_map), "-o", str(tmp_path / name), "--method", "mcl",
                     "-q", *extra]) == 0
    manifest = json.loads((tmp_path / "lost" / "manifest.json").read_text())
    assert any("cell there is unknown" in w for w in manifest["warnings"])
    assert manifest["extra"]["lost_after_s"] and manifest["extra"]["lost_after_s"][0] >= 2.0
    assert main(["evaluate", str(tmp_path / "lost"), str(tmp_path / "tracked"), "--reference", str(log), "-o",
                 str(tmp_path / "report"), "-q"]) == 0
    table = read_table("metrics", tmp_path / "report" / "metrics.parquet").to_pydict()
    got = {(r, m): v for r, m, v in zip(table["run"], table["metric"], table["value"], strict=True)}
    lost_run, tracked_run = (next(r for r, _ in got if r.endswith(n)) for n in ("lost", "tracked"))
    assert got[(lost_run, "lost")] == 1.0 and got[(lost_run, "time_to_lost_s")] >= 2.0
    assert got[(tracked_run, "lost")] == 0.0 and np.isnan(got[(tracked_run, "time_to_lost_s")])
    # another localizer's trajectory (a TUM file) says nothing about being lost: NaN, not 0
    assert main(["evaluate", str(tmp_path / "tracked" / "trajectory.tum"), "--reference", str(log), "-o",
                 str(tmp_path / "foreign"), "-q"]) == 0
    table = read_table("metrics", tmp_path / "foreign" / "metrics.parquet").to_pydict()
    lost = [v for m, v in zip(table["metric"], table["value"], strict=True) if m == "lost"]
    assert lost and all(np.isnan(v) for v in lost)


def test_a_start_yaw_beyond_a_turn_is_asked_about(sample_map: Path) -> None:
    from doorbatch.pipeline.localize.run import init_cell_note

    occ = load_localization_map(sample_map, LocalizeConfig()).occupancy
    i, j = (int(v[0]) for v in np.nonzero(occ.occupancy == 0))
    x, y = occ.cell_to_world([[i, j]])[0]
    assert init_cell_note(occ, (x, y, 1.5)) is None  # free, and a yaw in radians
    note = init_cell_note(occ, (x, y, 90.0))
    assert note is not None and "radians" in note and "1.571" in note


def test_an_initialpose_corrected_before_the_first_scan_starts_from_the_correction(sample_map: Path,
                                                                                    tmp_path: Path) -> None:
    """An operator's misclick 3 m off, corrected before the next scan: both messages fall on one scan, the start's;
    the correction is the start (it had been dropped silently: the run began 3 m off and stayed there)."""
    log, _ = _with_initial_poses(tmp_path, [(40, 3.0), (40, 0.2)])
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl",
                 "--init", "/initialpose", "-q"]) == 0
    err = _errors(run, log)
    assert err.mean() < 0.1


def test_annotated_map_to_odom_hangs_from_the_logs_odometry_frame(sample_map: Path, tmp_path: Path) -> None:
    """A Nav2 file's ``odom_frame_id: wheel_odom`` (frames.odom) on a log whose odometry is in ``odom``: the run
    read the log's odometry, but annotated.mcap's map→odom named wheel_odom, a tree the robot was not in, without
    a word. It names the log's odometry frame, with a warning."""
    from rosbags.highlevel import AnyReader

    run = tmp_path / "run"
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--set", "frames.odom=wheel_odom", "-q"]) == 0
    parents = set()
    with AnyReader([run / "annotated.mcap"]) as reader:
        for conn, _, raw in reader.messages([c for c in reader.connections if c.topic == "/tf"]):
            msg = reader.deserialize(raw, conn.msgtype)
            parents |= {(t.header.frame_id, t.child_frame_id) for t in msg.transforms}
    assert ("map", "odom") in parents and ("map", "wheel_odom") not in parents
    warnings = json.loads((run / "manifest.json").read_text())["warnings"]
    assert any("wheel_odom" in w and "map→odom" in w for w in warnings)


def test_a_run_with_one_update_over_many_scans_says_why(sample_map: Path, tmp_path: Path) -> None:
    """A PR2 tree whose fixed base_footprint → base_link edge was taken for the odometry gave 1 update over 489
    scans and exit 0 without a word. Odometry that never passes update_min_d / update_min_a is now warned (here by
    thresholds no motion of the log reaches)."""
    run = tmp_path / "run"
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--set", "localize.update_min_d=1000", "--set", "localize.update_min_a=1000",
                 "-q"]) == 0
    assert len(read_table("trajectory", run / "trajectory.parquet")) == 1
    warnings = json.loads((run / "manifest.json").read_text())["warnings"]
    assert any("1 filter update over" in w and "frames.odom" in w for w in warnings)


def test_door_states_name_each_door_by_its_door_id_in_the_map(sample_map: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A doors.parquet whose door_id are not the row numbers (a map edited or written by another tool): the
    door states and warnings had named the doors by their rows, so a join on door_id matched nothing or the
    wrong door, and the scoring read them as rows. Now they carry the map's door_id: the same run with the ids
    renumbered 100, 101, … is the same run, renamed, and scores the same."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    renamed = tmp_path / "map"
    shutil.copytree(sample_map, renamed)
    doors = pq.read_table(sample_map / "doors.parquet")
    ids = pa.array([100 + 7 * k for k in range(len(doors))], pa.int32())
    pq.write_table(doors.set_column(0, "door_id", ids), renamed / "doors.parquet")
    log, truth = SAMPLE_LOGS / "loc_partial.mcap", SAMPLE_LOGS / "loc_partial.truth.yaml"
    scores = []
    for name, map_dir in (("plain", sample_map), ("renamed", renamed)):
        run = tmp_path / name
        assert main(["localize", str(log), "--map", str(map_dir), "-o", str(run), "--method", "rbpf",
                     "--set", "seed=5", "-q"]) == 0
        assert main(["evaluate", str(run), "--reference", str(log), "--world", str(truth), "-o",
                     str(tmp_path / f"{name}_eval"), "-q"]) == 0
        table = read_table("metrics", tmp_path / f"{name}_eval" / "metrics.parquet").to_pydict()
        scores.append({m: v for m, v in zip(table["metric"], table["value"], strict=True) if m.startswith("door")})
    plain = read_table("door_states", tmp_path / "plain" / "door_states.parquet").to_pydict()
    named = read_table("door_states", tmp_path / "renamed" / "door_states.parquet").to_pydict()
    assert named["door_id"] == [100 + 7 * k for k in plain["door_id"]]
    assert named["angle"] == plain["angle"]
    from doorbatch.io.reader import open_log

    with open_log(tmp_path / "renamed" / "annotated.mcap") as reader:  # the door markers carry the ids too
        ids = {m.id for raw in reader.raw_messages() if raw.topic == "/doorbatch/doors" for m in raw.msg.markers}
    assert ids == set(named["door_id"])
    assert scores[0] == scores[1] and scores[0]["door_state_error_mean"] < math.radians(5.0)
    # the map renumbered again since the run: its door states are not scored, and evaluate says why
    shutil.copy(sample_map / "doors.parquet", renamed / "doors.parquet")
    capsys.readouterr()
    assert main(["evaluate", str(tmp_path / "renamed"), "--reference", str(log), "--world", str(truth), "-o",
                 str(tmp_path / "stale_eval")]) == 0
    assert "its door states name door_id 100, 107, 114" in capsys.readouterr().err


def _tf_moved(tmp_path: Path, shift: Callable[[float], tuple[float, float, float]]) -> Path:
    """loc_open.mcap with /tf's odom→base_link moved by ``shift(t)`` (x, y, yaw in odom; t s from the first
    message) and /odom left as it was: an EKF's tree beside the wheels' topic, or a driver whose restart the
    topic does not show."""
    from doorbatch.geometry.rotations import quaternion_to_matrix, yaw_of_matrix
    from doorbatch.geometry.se2 import compose
    from doorbatch.io import ros_messages
    from doorbatch.io.log_writer import LogWriter
    from doorbatch.io.reader import open_log

    log = tmp_path / "tf_moved.mcap"
    t0 = None
    with open_log(SAMPLE_LOGS / "loc_open.mcap") as reader, LogWriter(log) as writer:
        for raw in reader.raw_messages():
            t0 = raw.log_time_ns if t0 is None else t0
            msg = raw.msg
            if raw.topic == "/tf":
                moved = []
                for tr in msg.transforms:
                    if (tr.header.frame_id, tr.child_frame_id) == ("odom", "base_link"):
                        q = tr.transform.rotation
                        p = compose(np.array(shift((raw.log_time_ns - t0) / 1e9)), np.array(
                            [tr.transform.translation.x, tr.transform.translation.y,
                             yaw_of_matrix(quaternion_to_matrix([q.x, q.y, q.z, q.w]))]))
                        stamp = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
                        tr = ros_messages.planar_transform(stamp, "odom", "base_link", *p)
                    moved.append(tr)
                msg = ros_messages.tf_message(moved)
            writer.write(raw.topic, raw.msgtype, raw.log_time_ns, msg, raw.store)
    return log


def _drawn_off_m(run: Path) -> np.ndarray:
    """Per update, how far from the estimate a viewer draws base_link from annotated.mcap's own TF tree (its
    map→odom, the log's odom→base_link)."""
    from doorbatch.io.reader import open_log
    from doorbatch.io.recording import read_transforms

    with open_log(run / "annotated.mcap") as reader:
        tf = read_transforms(reader, DoorbatchConfig())
    traj = read_table("trajectory", run / "trajectory.parquet").to_pydict()
    drawn = np.array([tf.lookup("map", "base_link", int(t))[:2, 3] for t in traj["stamp_ns"]])
    return np.hypot(drawn[:, 0] - np.asarray(traj["x"]), drawn[:, 1] - np.asarray(traj["y"]))


def test_annotated_map_to_odom_puts_the_robot_of_the_logs_tf_tree_at_the_estimate(sample_map: Path,
                                                                                   tmp_path: Path) -> None:
    """/odom from the wheels, /tf odom→base_link from an EKF that drifts from them (5 cm/s along x, 1°/s): the
    run moves by /odom, but annotated.mcap's map→odom is put on the tree a viewer draws the robot from. It had been
    computed against /odom: hAJ's robot was drawn 2.3 m from the estimate."""
    log = _tf_moved(tmp_path, lambda t: (0.05 * t, 0.0, math.radians(1.0) * t))
    run = tmp_path / "run"
    assert main(["localize", str(log), "--map", str(sample_map), "-o", str(run), "--method", "mcl", "-q"]) == 0
    off = _drawn_off_m(run)
    assert off.size > 50 and off.max() < 1e-3


def test_localize_interrupted_while_writing_leaves_the_run_folder_as_it_was(
        sample_map: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGTERM while annotated.mcap was written (minutes on an hour's log): exit 130, and the earlier run in the
    folder untouched. Before, its trajectory had been replaced while its manifest stayed (hAM)."""
    import doorbatch.io.annotated_mcap as annotated

    run = tmp_path / "run"
    run.mkdir()
    earlier = {"manifest.json": "{}", "trajectory.tum": "0 0 0 0 0 0 0 1\n", "notes.txt": "mine"}
    for name, text in earlier.items():
        (run / name).write_text(text)

    def killed(*_: Any, **__: Any) -> None:
        raise KeyboardInterrupt("signal 15")

    monkeypatch.setattr(annotated, "write_annotated_mcap", killed)
    assert main(["localize", str(SAMPLE_LOGS / "loc_open.mcap"), "--map", str(sample_map), "-o", str(run),
                 "--method", "mcl", "--particles", "300", "-q"]) == 130
    assert {p.name: p.read_text() for p in run.iterdir()} == earlier
    assert [p.name for p in tmp_path.iterdir()] == ["run"]
