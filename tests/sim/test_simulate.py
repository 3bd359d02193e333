"""The simulator end to end: deterministic bytes, three formats that read back alike, truth files, topics."""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sim_helpers import OFFICE, office, short_scenario, write_scenario

from doorbatch.cli import main
from doorbatch.config import DoorPoseConfig
from doorbatch.errors import ConfigError
from doorbatch.io.map_server import read_map
from doorbatch.io.reader import open_log
from doorbatch.io.sim_truth import read_truth
from doorbatch.io.tum import read_tum
from doorbatch.records import BeamColors, Detections, Pose2D, Role, Scan, Transform, class_name
from doorbatch.sim.scenario import configs_dir, load_scenario, resolve_scenario
from doorbatch.sim.simulate import SimulationSummary, output_paths, random_streams, run_simulation, simulate
from doorbatch.sim.timeline import plan_scenario
from doorbatch.sim.truthmap import truth_maps
from doorbatch.sim.world import door_leaf_segments

MOVING_DOOR = {"changes": [{"door": "d02", "at_s": 1.0, "to_state": "open", "duration_s": 1.0}]}


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A ~6 s scenario with every sensor, a person and a door moving mid-pass."""
    sc = short_scenario(passes=[{"name": "p1", "waypoints_m": [[2.0, 0.0], [6.0, 0.0]], "dwell_s": 0.5,
                                 "doors": "mixed", **MOVING_DOOR}],
                        people=[{"name": "p", "waypoints_m": [[9.0, -0.6], [2.0, -0.6]], "speed_mps": 1.2}])
    return write_scenario(tmp_path_factory.mktemp("scn") / "short.yaml", sc)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory, scenario_file: Path) -> dict[str, SimulationSummary]:
    """The same simulation written as mcap (twice, in two folders), bag and rosbag2; and with another seed."""
    root = tmp_path_factory.mktemp("runs")
    return {
        "mcap": run_simulation(OFFICE, root / "a" / "run.mcap", scenario_file, seed=3, fmt="mcap"),
        "mcap_again": run_simulation(OFFICE, root / "b" / "run.mcap", scenario_file, seed=3, fmt="mcap"),
        "other_seed": run_simulation(OFFICE, root / "c" / "run.mcap", scenario_file, seed=4, fmt="mcap"),
        "bag": run_simulation(OFFICE, root / "d" / "run.bag", scenario_file, seed=3, fmt="bag"),
        "rosbag2": run_simulation(OFFICE, root / "e" / "run", scenario_file, seed=3, fmt="rosbag2"),
    }


def _files(summary: SimulationSummary) -> list[Path]:
    return [summary.log_path, summary.truth_path, summary.trajectory_path, summary.map_closed_path,
            summary.map_static_path, summary.map_closed_path.with_suffix(".pgm"),
            summary.map_static_path.with_suffix(".pgm")]


def test_same_seed_gives_byte_identical_files(runs: dict[str, SimulationSummary]) -> None:
    for a, b in zip(_files(runs["mcap"]), _files(runs["mcap_again"]), strict=True):
        assert a.read_bytes() == b.read_bytes(), a.name


def test_same_seed_gives_byte_identical_rosbag2_folders(runs: dict[str, SimulationSummary], scenario_file: Path,
                                                        tmp_path: Path) -> None:
    """Also from another process: nothing of the writer's temporary names (its pid) may reach the files."""
    other = tmp_path / "g" / "run"
    code = (f"from pathlib import Path; from doorbatch.sim.simulate import run_simulation; "
            f"run_simulation(Path({str(OFFICE)!r}), Path({str(other)!r}), Path({str(scenario_file)!r}), seed=3, "
            f"fmt='rosbag2')")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=Path(__file__).resolve().parents[2])
    a, b = runs["rosbag2"].log_path, other
    names = sorted(p.name for p in a.iterdir())
    assert names == sorted(p.name for p in b.iterdir()) == ["metadata.yaml", "run.db3"]  # not its temporary name
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name


def test_different_seed_gives_different_log(runs: dict[str, SimulationSummary]) -> None:
    assert runs["mcap"].log_path.read_bytes() != runs["other_seed"].log_path.read_bytes()
    assert runs["mcap"].message_counts.keys() == runs["other_seed"].message_counts.keys()


def _records(path: Path) -> dict[Role, list[object]]:
    out: dict[Role, list[object]] = {}
    with open_log(path) as reader:
        for rm in reader.messages():
            out.setdefault(rm.role, []).append(rm.record)
    return out


def test_three_formats_read_back_identically(runs: dict[str, SimulationSummary]) -> None:
    logs = {fmt: _records(runs[fmt].log_path) for fmt in ("mcap", "bag", "rosbag2")}
    ref = logs["mcap"]
    assert set(ref) == set(Role)
    for fmt in ("bag", "rosbag2"):
        got = logs[fmt]
        assert {r: len(v) for r, v in got.items()} == {r: len(v) for r, v in ref.items()}, fmt
        for role in Role:
            assert [(r.stamp_ns, r.log_time_ns if hasattr(r, "log_time_ns") else 0) for r in got[role]] == [  # type: ignore[attr-defined]
                (r.stamp_ns, r.log_time_ns if hasattr(r, "log_time_ns") else 0) for r in ref[role]], (fmt, role)  # type: ignore[attr-defined]
        for a, b in zip(got[Role.SCAN], ref[Role.SCAN], strict=True):
            np.testing.assert_array_equal(a.ranges, b.ranges)  # type: ignore[attr-defined]
        for a, b in zip(got[Role.COLORS], ref[Role.COLORS], strict=True):
            np.testing.assert_array_equal(a.rgb, b.rgb)  # type: ignore[attr-defined]
            np.testing.assert_array_equal(a.points, b.points)  # type: ignore[attr-defined]
        for a, b in zip(got[Role.IMAGE], ref[Role.IMAGE], strict=True):
            np.testing.assert_array_equal(a.pixels, b.pixels)  # type: ignore[attr-defined]
        names = DoorPoseConfig().class_names  # a ROS 1 bag's ids are label indices ("0"), resolved by class_names
        for a, b in zip(got[Role.DETECTIONS], ref[Role.DETECTIONS], strict=True):
            resolved = [replace(d, class_id=class_name(d.class_id, names)) for d in a.detections]  # type: ignore[attr-defined]
            assert replace(a, detections=tuple(resolved)) == b  # type: ignore[arg-type]
        for a, b in zip(got[Role.ODOMETRY], ref[Role.ODOMETRY], strict=True):
            assert (a.x, a.y, a.yaw) == (b.x, b.y, b.yaw)  # type: ignore[attr-defined]


def test_log_has_every_topic_with_aligned_colors_and_frames(runs: dict[str, SimulationSummary]) -> None:
    summary = runs["mcap"]
    assert set(summary.message_counts) == {"/scan", "/scan_colors", "/odom", "/tf", "/tf_static", "/ground_truth",
                                           "/camera/image_raw", "/camera/camera_info", "/detections"}
    assert summary.start_ns == 1_700_000_000 * 10**9
    rec = _records(summary.log_path)
    scans = [s for s in rec[Role.SCAN] if isinstance(s, Scan)]
    colors = [c for c in rec[Role.COLORS] if isinstance(c, BeamColors)]
    assert [s.stamp_ns for s in scans] == [c.stamp_ns for c in colors]
    for scan, col in zip(scans, colors, strict=True):
        assert scan.frame_id == col.frame_id == "laser"
        assert col.points.shape[0] == scan.ranges.shape[0]
        valid = np.isfinite(scan.ranges)
        assert np.all(np.isnan(col.points[~valid])) and np.all(np.isfinite(col.points[valid]))
        expected = scan.ranges[valid, None] * np.stack([np.cos(scan.angles[valid]), np.sin(scan.angles[valid])], 1)
        np.testing.assert_allclose(col.points[valid, :2], expected, rtol=1e-6, atol=1e-6)
    assert any(np.isnan(s.ranges).any() for s in scans) and any(np.isposinf(s.ranges).any() for s in scans)
    static = {(t.parent, t.child) for t in rec[Role.TRANSFORMS] if isinstance(t, Transform) and t.static}
    assert static == {("base_link", "laser"), ("base_link", "camera_optical")}
    odom = [p for p in rec[Role.ODOMETRY] if isinstance(p, Pose2D)]
    ref = [p for p in rec[Role.REFERENCE] if isinstance(p, Pose2D)]
    assert odom[0].frame_id == "odom" and ref[0].frame_id == "map"
    assert (odom[0].x, odom[0].y) == (0.0, 0.0)  # odometry starts at its own origin
    dets = [d for d in rec[Role.DETECTIONS] if isinstance(d, Detections)]
    classes = {x.class_id for d in dets for x in d.detections}
    assert classes <= {"door", "handle"} and "door" in classes


def test_truth_file_holds_the_world_door_angles_and_trajectory(runs: dict[str, SimulationSummary],
                                                               scenario_file: Path) -> None:
    summary = runs["mcap"]
    truth = read_truth(summary.truth_path)
    world = office()
    assert truth.files == {k: p.name for k, p in output_paths(summary.log_path).items()}
    assert len(truth.doors) == world.doors.count
    d2 = truth.doors[world.doors.index("d02")]
    assert (d2.hinge_x, d2.hinge_y, d2.length, d2.opening_sign) == (5.6, -1.1, 0.9, -1)
    assert d2.max_angle == pytest.approx(math.radians(100))
    np.testing.assert_allclose(truth.segments, world.segments)
    # door d02 opens during the pass: the table has its knots; the truth agrees with the plan
    plan = plan_scenario(world, load_scenario(scenario_file), random_streams(3)["scenario"])
    stamps = truth.start_ns + np.arange(0, int(plan.end_s * 1e9), 50_000_000)
    expected = plan.doors.angles_at((stamps - truth.start_ns) / 1e9) * world.doors.opening_sign
    np.testing.assert_allclose(truth.door_angles_at(stamps), expected, atol=1e-9)
    i = world.doors.index("d02")
    assert truth.door_angles_at([truth.start_ns])[0, i] != truth.door_angles_at([truth.end_ns])[0, i]
    tum = read_tum(summary.trajectory_path)
    with open_log(summary.log_path) as reader:
        gt = [rm.record for rm in reader.messages([Role.REFERENCE])]
    assert len(tum.stamp_ns) == len(gt)
    np.testing.assert_allclose(tum.x, [p.x for p in gt])  # type: ignore[attr-defined]


def test_truth_maps_draw_doors_closed_or_leave_them_out(runs: dict[str, SimulationSummary]) -> None:
    closed, static = read_map(runs["mcap"].map_closed_path), read_map(runs["mcap"].map_static_path)
    assert closed.resolution_m == pytest.approx(0.05)
    world = office()
    leaves = door_leaf_segments(world.doors, np.zeros(world.doors.count))
    mid = closed.world_to_cell(leaves.mean(axis=1))  # leaf centres
    assert np.all(closed.occupancy[mid[:, 0], mid[:, 1]] == 100)
    assert np.all(static.occupancy[mid[:, 0], mid[:, 1]] == 0)
    hinge = static.world_to_cell(world.doors.hinge_xy)
    assert np.all(static.occupancy[hinge[:, 0], hinge[:, 1]] == 100)  # hinge cells stay occupied
    corridor = static.world_to_cell(np.array([[20.0, 0.0], [20.0, 3.0], [15.0, -3.0]]))  # corridor and rooms
    assert np.all(static.occupancy[corridor[:, 0], corridor[:, 1]] == 0)
    outside = static.world_to_cell(np.array([[20.0, 4.8]]))
    assert static.occupancy[outside[0, 0], outside[0, 1]] == -1


def test_truth_map_walls_lie_on_cell_centres() -> None:
    """The office's walls run along y = ±1.1 and x = 0: each must fill the row/column of cells whose centres
    lie on it, not a neighbour half a cell (2.5 cm) to one side, or every filter scored on the truth map
    carries that offset."""
    world = office()
    _, static = truth_maps(world, (1.0, 0.0), resolution_m=0.05)
    for xy, axis in (((18.3, 1.1), 1), ((18.3, -1.1), 1), ((0.0, 0.3), 0)):
        ij = static.world_to_cell(np.array([xy]))
        assert static.occupancy[ij[0, 0], ij[0, 1]] == 100
        assert static.cell_to_world(ij)[0, axis] == pytest.approx(xy[axis], abs=1e-9)


def test_simulate_yields_messages_in_log_time_order() -> None:
    sc = short_scenario(sensors={"camera": {"enabled": False}, "detections": {"enabled": False}})
    stamps = [m.log_time_ns for m in simulate(office(), sc, seed=1)]
    assert stamps == sorted(stamps) and len(stamps) > 500


def test_scenario_names_resolve_to_shipped_files_and_paths_pass_through(tmp_path: Path) -> None:
    assert resolve_scenario(None) == configs_dir() / "scenarios" / "default.yaml"
    assert resolve_scenario("loc_open") == configs_dir() / "scenarios" / "loc_open.yaml"
    own = write_scenario(tmp_path / "mine.yaml", short_scenario())
    assert resolve_scenario(own) == own
    with pytest.raises(ConfigError, match="loc_open"):
        resolve_scenario("loc_opn")


def test_route_through_a_closed_door_is_rejected() -> None:
    sc = short_scenario(passes=[{"name": "p1", "waypoints_m": [[3.45, 0.0], [3.45, 2.5]], "doors": "closed"}])
    with pytest.raises(ConfigError, match="door d01"):
        plan_scenario(office(), sc, random_streams(0)["scenario"])


def test_unknown_scenario_key_names_its_path() -> None:
    with pytest.raises(ConfigError, match=r"sensors\.laser\.sigma"):
        short_scenario(sensors={"laser": {"sigma": 0.1}})


def test_fixed_doors_never_move_between_passes() -> None:
    sc = load_scenario("mapping_pass")
    plan = plan_scenario(office(), sc, random_streams(0)["scenario"])
    doors = office().doors
    t = np.linspace(0.0, plan.end_s, 400)
    angles = plan.doors.angles_at(t)
    for name in sc.fixed_doors:
        assert np.ptp(angles[:, doors.index(name)]) == 0.0
    assert np.ptp(angles[:, doors.index("d01")]) > 1.0  # d01: closed, open, partial
    assert len(plan.passes) == 3


def test_logged_odometry_increments_have_the_model_statistics(tmp_path: Path) -> None:
    from doorbatch.sim.motion import odometry_increments

    sc = short_scenario(
        passes=[{"name": "p1", "route": "main", "dwell_s": 0.5, "doors": "closed"}],
        sensors={"laser": {"enabled": False}, "colors": {"enabled": False}, "camera": {"enabled": False},
                 "detections": {"enabled": False}, "ground_truth": {"rate_hz": 50.0},
                 "odometry": {"alpha1": 0.05, "alpha2": 0.01, "alpha3": 0.03, "alpha4": 0.01,
                              "scale_error": 0.02, "yaw_drift_rad_per_m": 0.01}},
    )
    summary = run_simulation(OFFICE, tmp_path / "odom.mcap", write_scenario(tmp_path / "s.yaml", sc), seed=11)
    poses: dict[Role, list[Pose2D]] = {Role.ODOMETRY: [], Role.REFERENCE: []}
    with open_log(summary.log_path) as reader:
        for rm in reader.messages([Role.ODOMETRY, Role.REFERENCE]):
            if rm.topic in ("/odom", "/ground_truth"):
                poses[rm.role].append(rm.record)  # type: ignore[arg-type]
    odom, gt = poses[Role.ODOMETRY], poses[Role.REFERENCE]
    assert [p.stamp_ns for p in odom] == [p.stamp_ns for p in gt] and len(odom) > 2000

    def inc(ps: list[Pose2D]) -> object:
        return odometry_increments(np.array([p.x for p in ps]), np.array([p.y for p in ps]),
                                   np.array([p.yaw for p in ps]))

    rep, true = inc(odom), inc(gt)
    o = sc.sensors.odometry
    r1, tr, r2 = true.rot1, true.trans, true.rot2  # type: ignore[attr-defined]
    model = {  # component: (error, model mean, model std)
        "rot1": (rep.rot1 - r1, 0.0 * tr, np.sqrt(o.alpha1 * r1**2 + o.alpha2 * tr**2)),  # type: ignore[attr-defined]
        "trans": (rep.trans - tr, o.scale_error * tr,  # type: ignore[attr-defined]
                  np.sqrt(o.alpha3 * tr**2 + o.alpha4 * (r1**2 + r2**2))),
        "rot2": (rep.rot2 - r2, o.yaw_drift_rad_per_m * tr, np.sqrt(o.alpha1 * r2**2 + o.alpha2 * tr**2)),  # type: ignore[attr-defined]
    }
    for name, (err, mean, sd) in model.items():
        moving = sd > 1e-9
        assert moving.sum() > 1500, name
        z = (np.asarray(err)[moving] - mean[moving]) / sd[moving]
        assert z.std() == pytest.approx(1.0, rel=0.10), name
        assert abs(z.mean()) < 0.1, name
    # the systematic part is there: odometry drifts away from the truth over the corridor
    end_error = math.hypot(odom[-1].x - (gt[-1].x - gt[0].x), odom[-1].y - (gt[-1].y - gt[0].y))
    assert end_error > 0.3


@pytest.mark.parametrize(("args", "code"), [(["-o", "x.bag", "--format", "mcap"], 2),
                                            (["-o", "x.mcap", "--format", "rosbag2"], 2),
                                            (["-o", "x.txt", "--format", "bag"], 2)])
def test_an_output_name_that_does_not_fit_the_format_is_a_usage_error(tmp_path: Path, scenario_file: Path,
                                                                      args: list[str], code: int) -> None:
    args = [a if not a.startswith("x.") else str(tmp_path / a) for a in args]
    assert main(["simulate", str(OFFICE), "--scenario", str(scenario_file), *args, "-q"]) == code
    assert not any(tmp_path.iterdir())


def test_the_format_follows_the_output_suffix(tmp_path: Path, scenario_file: Path) -> None:
    assert main(["simulate", str(OFFICE), "--scenario", str(scenario_file), "-o", str(tmp_path / "x.bag"), "-q"]) == 0
    assert (tmp_path / "x.bag").read_bytes().startswith(b"#ROSBAG V2.0")


def test_a_rosbag2_output_never_replaces_a_file(tmp_path: Path, scenario_file: Path) -> None:
    notes = tmp_path / "notes"
    notes.write_text("precious")
    assert main(["simulate", str(OFFICE), "--scenario", str(scenario_file), "-o", str(notes), "-q"]) == 2
    assert notes.read_text() == "precious"
