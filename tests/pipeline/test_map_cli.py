"""doorbatch map end to end on the sample's mapping passes, and its clear errors."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig, load_config
from doorbatch.io import ros_messages as m
from doorbatch.io.map_server import read_map
from doorbatch.io.parquet import read_table
from doorbatch.pipeline.mapping import build_map
from tests.conftest import REPO, T0, sample_messages

SAMPLE_LOGS = REPO / "datasets" / "sample" / "logs"


def test_map_on_the_sample_writes_the_map_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    logs = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]
    out = tmp_path / "map"
    assert main(["map", *logs, "-o", str(out), "--stages", "grid", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["pose_source"] == "reference" and summary["passes"] == 3
    occ = read_map(out / "map.yaml")
    assert occ.resolution_m == pytest.approx(0.05)
    assert (occ.occupancy == 100).sum() > 1000 and (occ.occupancy == 0).sum() > 10000
    doors = read_table("doors", out / "doors.parquet").to_pydict()
    assert len(doors["door_id"]) == summary["doors"] >= 1
    assert set(doors["source"]) == {"grid"}
    assert all(0.6 <= length <= 1.2 for length in doors["length"])
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["extra"]["pose_source"] == "reference"
    assert len(manifest["inputs"]) == 3 and manifest["config_hash"]
    assert (out / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not any("one pass" in w for w in manifest["warnings"])


def test_one_pass_is_told_that_it_finds_few_doors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One mapping pass found 2 of 10 doors, the leaves that swung in view left in map.pgm, and said nothing."""
    out = tmp_path / "map"
    assert main(["map", str(SAMPLE_LOGS / "map_pass1.mcap"), "-o", str(out), "--stages", "grid", "--json"]) == 0
    warnings = json.loads((out / "manifest.json").read_text())["warnings"]
    assert any("one pass" in w and "mapping.pass_duration_s" in w for w in warnings)


def _with_reference_frame(frame: str) -> list[tuple[str, str, int, object]]:
    msgs = []
    for topic, msgtype, t, msg in sample_messages(8):
        if topic == "/ground_truth":
            p = msg.pose.pose.position
            msg = m.odometry(t, frame, "base_link", p.x, p.y, 0.0)
        msgs.append((topic, msgtype, t, msg))
    return msgs


def test_passes_with_disjoint_frames_are_an_error(write_log: Callable[..., Path], tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    a = write_log("a.mcap", _with_reference_frame("map"))
    b = write_log("b.mcap", _with_reference_frame("world"))
    code = main(["map", str(a), str(b), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 3 and "disjoint coordinate frames" in err
    assert not (tmp_path / "out" / "map.yaml").exists()


def test_pieces_of_one_recording_given_out_of_order_are_mapped_in_time_order(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The sample's passes are one recording in three pieces. Given as 3, 1, 2 (a glob sorts run_10 before
    run_2) their odometry does not chain, which was refused as disjoint frames; in the order of their first stamps
    it does: mapped in that order, the map the right order gives, and a warning that says so."""
    logs = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]
    args = ["--stages", "grid", "--pose-source", "odometry", "--json"]
    assert main(["map", *logs, "-o", str(tmp_path / "given"), *args]) == 0
    assert not any("order" in w for w in json.loads(capsys.readouterr().out)["warnings"])
    assert main(["map", logs[2], logs[0], logs[1], "-o", str(tmp_path / "shuffled"), *args]) == 0
    warnings = json.loads(capsys.readouterr().out)["warnings"]
    assert any("order of their first scans' times" in w and "map_pass1.mcap, map_pass2.mcap, map_pass3.mcap" in w
               for w in warnings)
    assert (tmp_path / "shuffled" / "map.pgm").read_bytes() == (tmp_path / "given" / "map.pgm").read_bytes()
    manifest = json.loads((tmp_path / "shuffled" / "manifest.json").read_text())
    assert [Path(i["path"]).name for i in manifest["inputs"]] == [Path(p).name for p in logs]


def test_passes_recorded_apart_and_listed_out_of_order_are_mapped_in_the_order_they_happened(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Passes whose odometry chains in no order (as if recorded apart), listed 3, 1, 2 with a reference: the grid
    stage classifies each pass against those before it, so the listed order gave other doors; they are mapped in
    time order, the map of 1, 2, 3, with a warning."""
    import doorbatch.pipeline.mapping as mapping

    monkeypatch.setattr(mapping, "continues", lambda *_: False)
    logs = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]
    args = ["--stages", "grid", "--pose-source", "reference", "--json"]
    assert main(["map", *logs, "-o", str(tmp_path / "given"), *args]) == 0
    capsys.readouterr()
    assert main(["map", logs[2], logs[0], logs[1], "-o", str(tmp_path / "shuffled"), *args]) == 0
    warnings = json.loads(capsys.readouterr().out)["warnings"]
    assert any("order of their first scans' times" in w for w in warnings)
    for name in ("map.pgm", "doors.parquet"):
        assert (tmp_path / "shuffled" / name).read_bytes() == (tmp_path / "given" / name).read_bytes()


def test_passes_in_sim_time_are_ordered_by_when_they_were_recorded() -> None:
    """Three Gazebo runs recorded an hour apart, each in sim time from its own launch (300 s, 5 s, 3 s in): their
    stamps say 3, 2, 1, the recorder's clock 1, 2, 3. Given 1, 2, 3 they stay so (they were reordered by sim time,
    and a person's trace gave a false door in that order); given 3, 1, 2 they are put back to 1, 2, 3."""
    from doorbatch.io.log_clock import LogClock
    from doorbatch.io.recording import Recording, ScanSet
    from doorbatch.pipeline.mapping import time_order

    def run(sim_start_s: float, recorded_at_s: float) -> Recording:
        stamps = np.int64(sim_start_s * 1e9) + np.arange(100, dtype=np.int64) * 100_000_000
        n = len(stamps)
        scans = ScanSet(stamps, [np.ones(4, np.float32)] * n, np.zeros(n), np.full(n, 0.1), np.zeros(n),
                        np.full(n, 10.0), np.zeros((n, 2, 3)), "laser")
        clock = LogClock.constant(int((recorded_at_s - sim_start_s) * 1e9))
        return Recording(f"run_{recorded_at_s:.0f}.bag", scans, None, None, log_clock=clock)

    runs = [run(300.0, 1.7e9), run(5.5, 1.7e9 + 3600), run(2.9, 1.7e9 + 7200)]
    config = DoorbatchConfig()
    assert time_order(runs, config) is None
    assert time_order([runs[2], runs[0], runs[1]], config) == [1, 2, 0]
    one_clock = [run(t, t) for t in (100.0, 0.0, 50.0)]  # no sim time: stamps and log times agree
    assert time_order(one_clock, config) == [1, 2, 0]


def test_a_log_without_any_pose_source_is_an_error(write_log: Callable[..., Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    bare = [x for x in sample_messages(5) if x[0] not in ("/odom", "/ground_truth", "/tf")]
    code = main(["map", str(write_log("bare.mcap", bare)), "-o", str(tmp_path / "out"), "--pose-source", "reference"])
    err = capsys.readouterr().err
    assert code == 3 and "no usable pose source" in err and "bare.mcap" in err


def test_a_log_with_scans_alone_is_scan_matched_when_asked(write_log: Callable[..., Path], tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """No reference, no odometry (a handheld lidar): without --pose-source a clear error that names the way;
    --pose-source scanmatch maps from the scans alone and says so."""
    bare = [x for x in sample_messages(5) if x[0] not in ("/odom", "/ground_truth", "/tf")]
    log = write_log("bare.mcap", bare)
    out = tmp_path / "out"
    assert main(["map", str(log), "-o", str(out)]) == 3
    assert "--pose-source scanmatch" in capsys.readouterr().err and not out.exists()
    assert main(["map", str(log), "-o", str(out), "--pose-source", "scanmatch", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "scanmatch"
    warnings = json.loads((out / "manifest.json").read_text())["warnings"]
    assert any("no odometry" in w and "constant velocity" in w for w in warnings)


def _nav2_like(reference_every: int | None) -> list[tuple[str, str, int, object]]:
    """The sample messages without ground truth, plus what a Nav2 robot's log holds: an RViz /initialpose and a
    /goal_pose, and (``reference_every``) /amcl_pose published on every n-th scan only."""
    msgs: list[tuple[str, str, int, object]] = []
    for i, (topic, msgtype, t, msg) in enumerate(x for x in sample_messages(20) if x[0] != "/ground_truth"):
        msgs.append((topic, msgtype, t, msg))
        if i == 3:
            msgs.append(("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", t + 50_000_000,
                         m.pose_with_covariance_stamped(t + 50_000_000, "map", 0.0, 0.0, 0.0, [0.0] * 36)))
            msgs.append(("/goal_pose", "geometry_msgs/msg/PoseStamped", t, m.pose_stamped(t, "map", 9.0, 1.0, 0.0)))
    if reference_every is not None:
        scans = [t for topic, _, t, _ in msgs if topic == "/scan"]
        for k, t in enumerate(scans[::reference_every]):
            msgs.append(("/amcl_pose", "geometry_msgs/msg/PoseWithCovarianceStamped", t,
                         m.pose_with_covariance_stamped(t, "map", 0.1 * k, 0.0, 0.0, [0.0] * 36)))
    return sorted(msgs, key=lambda x: x[2])


def test_goals_and_initial_poses_are_not_the_reference(write_log: Callable[..., Path], tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    # before: /initialpose (one message) became the reference, every scan was skipped, and an empty map exit 0
    log = write_log("nav2.mcap", _nav2_like(None))
    assert main(["inspect", str(log), "--json"]) == 0
    roles = {t["name"]: t.get("role") for t in json.loads(capsys.readouterr().out)["topics"]}
    assert roles["/initialpose"] is None and roles["/goal_pose"] is None
    out = tmp_path / "out"
    assert main(["map", str(log), "-o", str(out), "--stages", "grid", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "scanmatch"
    assert (read_map(out / "map.yaml").occupancy == 100).sum() > 100



def _auto_pose_source(log: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[str, str]:
    """``doorbatch map LOG`` (grid stage) without --pose-source: the source it chose and its manifest's warnings."""
    assert main(["map", str(log), "-o", str(out), "--stages", "grid", "--json"]) == 0
    chosen = json.loads(capsys.readouterr().out)["pose_source"]
    return chosen, " ".join(json.loads((out / "manifest.json").read_text()).get("warnings", []))

@pytest.mark.parametrize(("every", "source"), [(1, "reference"), (2, "reference"), (10, "scanmatch")])
def test_auto_takes_the_reference_only_where_it_covers_the_scans(write_log: Callable[..., Path], tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str], every: int,
                                                                source: str) -> None:
    # /amcl_pose on every scan, every 2nd (0.2 s apart: all scans within max_pose_gap_s) or every 10th (1 s gaps)
    chosen, warnings = _auto_pose_source(write_log("nav2.mcap", _nav2_like(every)), tmp_path / "out", capsys)
    assert chosen == source
    assert ("cover" in warnings) == (source == "scanmatch")


def test_a_reference_that_gives_no_scan_a_pose_is_an_error(write_log: Callable[..., Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    log = write_log("nav2.mcap", _nav2_like(None))
    code = main(["map", str(log), "-o", str(tmp_path / "out"), "--pose-source", "reference",
                 "--set", "topics.reference=/initialpose"])
    err = capsys.readouterr().err
    assert code == 3 and "no scan has a reference pose" in err
    assert not (tmp_path / "out" / "map.yaml").exists()


def test_a_short_range_lidar_clears_no_farther_than_its_range_max(write_log: Callable[..., Path]) -> None:
    """A 3.5 m lidar (TurtleBot3's LDS) that saw nothing: free space reaches 3.5 m round the path, not the
    configured 5 m no-return clearing (sensor_msgs/LaserScan: such a reading says nothing beyond range_max)."""
    msgs = []
    for topic, msgtype, t, msg in sample_messages(8):
        if topic == "/scan":
            msg = m.laser_scan(t, "laser", -np.pi, 2 * np.pi / 360, 0.12, 3.5, np.full(360, np.inf))
        msgs.append((topic, msgtype, t, msg))
    config = load_config(overrides=["grid.no_return_clear_m=5.0", "mapping.pose_source=reference"])
    grid = build_map([write_log("tb3.mcap", msgs)], config).static_map
    known = np.argwhere(grid.occupancy.T >= 0) * grid.resolution_m  # (x, y) offsets of the seen cells
    width_x, width_y = np.ptp(known, axis=0) + grid.resolution_m
    # The laser moves 0.7 m along x and 0.154 m along y: the union of 3.5 m discs round its positions.
    assert 2 * 3.5 < width_x <= 2 * 3.5 + 0.7 + 2 * grid.resolution_m
    assert 2 * 3.5 - 2 * grid.resolution_m < width_y <= 2 * 3.5 + 0.154 + 2 * grid.resolution_m


def test_odometry_pose_source_uses_odometry(write_log: Callable[..., Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["map", str(write_log("a.mcap")), "-o", str(out), "--pose-source", "odometry", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "odometry"
    assert np.isfinite(read_map(out / "map.yaml").origin_x_m)


def test_scanmatch_pose_source_is_used_and_recorded(write_log: Callable[..., Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["map", str(write_log("a.mcap")), "-o", str(out), "--pose-source", "scanmatch", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "scanmatch"
    assert json.loads((out / "manifest.json").read_text())["extra"]["pose_source"] == "scanmatch"
    assert np.isfinite(read_map(out / "map.yaml").origin_x_m)


def _topic_counts(path: Path) -> dict[str, int]:
    from rosbags.highlevel import AnyReader

    counts: dict[str, int] = {}
    with AnyReader([path]) as reader:
        for conn in reader.connections:
            counts[conn.topic] = counts.get(conn.topic, 0) + conn.msgcount
    return counts


def test_map_with_mcap_writes_the_passes_with_map_doors_poses_and_map_to_odom(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    logs = [SAMPLE_LOGS / f"map_pass{k}.mcap" for k in (1, 2, 3)]
    out = tmp_path / "map"
    assert main(["map", *map(str, logs), "-o", str(out), "--stages", "grid", "--mcap", "--json"]) == 0
    assert str(out / "annotated.mcap") in json.loads(capsys.readouterr().out)["files"]
    inputs = [_topic_counts(p) for p in logs]
    counts = _topic_counts(out / "annotated.mcap")
    for topic in ("/scan", "/odom", "/ground_truth"):  # every input message is kept
        assert counts[topic] == sum(c[topic] for c in inputs)
    scans = counts["/scan"]
    assert counts["/doorbatch/map"] == 1
    assert counts["/doorbatch/doors"] == 3  # the doors at the start of each pass
    assert counts["/doorbatch/pose"] == scans  # every scan has a reference pose
    assert counts["/tf"] == sum(c["/tf"] for c in inputs) + scans  # plus map→odom per scan
    assert counts["/doorbatch/path"] == sum(-(-c["/scan"] // 10) for c in inputs)
    # the same folder again without --mcap: the old annotated.mcap is not left to pass for this map's
    assert main(["map", str(logs[0]), "-o", str(out), "--stages", "grid", "-q"]) == 0
    assert not (out / "annotated.mcap").exists() and (out / "map.yaml").is_file()


def test_map_never_removes_a_file_it_did_not_write_there(tmp_path: Path) -> None:
    """Only files an earlier doorbatch map left are cleared, and never an input: a log named annotated.mcap in
    the output folder stays."""
    out = tmp_path / "mapdir"
    out.mkdir()
    log = out / "annotated.mcap"
    log.write_bytes((SAMPLE_LOGS / "map_pass1.mcap").read_bytes())
    (out / "walls.parquet").write_text("a user's own file")
    for _ in range(2):  # the second run reads the first's manifest: still not its file
        assert main(["map", str(log), "-o", str(out), "--stages", "grid", "-q"]) == 0
        assert log.is_file() and (out / "walls.parquet").read_text() == "a user's own file"
    assert main(["map", str(log), "-o", str(out), "--stages", "grid", "--mcap", "-q"]) == 2  # over its input
    assert log.read_bytes() == (SAMPLE_LOGS / "map_pass1.mcap").read_bytes()



def _with_reference(reference: Callable[[float, float, float], tuple[float, float, float]]
                    ) -> list[tuple[str, str, int, object]]:
    """The sample messages with /ground_truth made from each scan's odometry pose by ``reference``."""
    msgs = [x for x in sample_messages(30) if x[0] != "/ground_truth"]  # 3 m of odometry path
    odometry_stamps = [t for topic, _, t, _ in msgs if topic == "/odom"]
    for k, t in enumerate(odometry_stamps):  # the sample's k-th odometry pose is (0.1 k, 0.02 k, 0.01 k)
        msgs.append(("/ground_truth", "nav_msgs/msg/Odometry", t,
                     m.odometry(t, "map", "base_link", *reference(0.1 * k, 0.02 * k, 0.01 * k))))
    return sorted(msgs, key=lambda x: x[2])


def _turned_and_moved(x: float, y: float, yaw: float) -> tuple[float, float, float]:
    c, s = np.cos(0.5), np.sin(0.5)
    return 3.0 + c * x - s * y, -2.0 + s * x + c * y, yaw + 0.5


@pytest.mark.parametrize(("reference", "source"), [
    (_turned_and_moved, "scanmatch"),  # the odometry again, in another frame: a raw CARMEN log's laser poses
    (lambda x, y, yaw: (1.01 * x, y, yaw - 0.02 * x), "reference"),  # 1 % and 1.1°/m off it: a reference
])
def test_auto_takes_no_reference_that_repeats_the_odometry(write_log: Callable[..., Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str],
                                                           reference: Callable[[float, float, float],
                                                                               tuple[float, float, float]],
                                                           source: str) -> None:
    log = write_log("copy.mcap", _with_reference(reference))
    chosen, warnings = _auto_pose_source(log, tmp_path / "out", capsys)
    assert chosen == source
    assert ("the odometry again" in warnings) == ("moved rigidly" in warnings) == (source == "scanmatch")
    # asked for, the reference is taken as it is (a corrected CARMEN log's poses equal its odometry too)
    assert main(["map", str(log), "-o", str(tmp_path / "asked"), "--stages", "grid", "--pose-source", "reference",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "reference"


def test_a_robot_that_barely_moved_cannot_tell_its_reference_from_its_odometry(write_log: Callable[..., Path]) -> None:
    """Under io.reference_repeats_min_path_m (2 m) of odometry path no odometry has drifted from any reference
    yet: the reference is not flagged, whatever it is (a robot watching doors move, standing still)."""
    from doorbatch.io.recording import load_recording

    short = [x for x in _with_reference(_turned_and_moved) if x[2] <= T0 + 1_500_000_000]  # 1.5 m
    assert not load_recording(write_log("short.mcap", short), DoorbatchConfig()).reference_is_odometry
    assert load_recording(write_log("long.mcap", _with_reference(_turned_and_moved)),
                          DoorbatchConfig()).reference_is_odometry


def test_passes_recorded_apart_under_a_localizer_map_in_its_map_frame(tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Two sample passes, each with its odometry from zero and no ground truth, but AMCL's map → odom on /tf:
    auto takes base_link in map as the reference, and the doors come where the ground truth puts them."""
    logs = [SAMPLE_LOGS / f"map_pass{k}.mcap" for k in (1, 2)]
    apart = [_recorded_apart(p, tmp_path / p.name, under_a_localizer=True) for p in logs]
    assert main(["map", *map(str, apart), "-o", str(tmp_path / "apart"), "--stages", "grid", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["pose_source"] == "reference"
    assert main(["map", *map(str, logs), "-o", str(tmp_path / "truth"), "--stages", "grid", "--json"]) == 0
    capsys.readouterr()
    got = read_table("doors", tmp_path / "apart" / "doors.parquet").to_pydict()
    want = read_table("doors", tmp_path / "truth" / "doors.parquet").to_pydict()
    assert len(got["door_id"]) == len(want["door_id"]) >= 2
    np.testing.assert_allclose(sorted(got["hinge_x"]), sorted(want["hinge_x"]), atol=0.02)
    assert main(["map", *(str(p) for p in apart), "-o", str(tmp_path / "odom"), "--pose-source", "odometry"]) == 3
    assert "disjoint coordinate frames" in capsys.readouterr().err  # without the localizer: refused, as before


def _recorded_apart(path: Path, out: Path, under_a_localizer: bool = False, yaw_drift_per_m: float = 0.0) -> Path:
    """A sample pass as its own recording: odometry from zero at the pass's start (turning ``yaw_drift_per_m`` rad
    more per metre driven than it did), no /ground_truth; under a localizer (AMCL), also its map → odom on /tf (here
    exact: truth ∘ odometry⁻¹ at each odometry stamp)."""
    from doorbatch.geometry.se2 import compose, interpolate_poses, inverse, relative
    from doorbatch.io.reader import open_log
    from tests.conftest import write_messages

    with open_log(path, DoorbatchConfig()) as reader:
        raws = list(reader.raw_messages())
    truth = [_planar_odometry(r.msg) for r in raws if r.topic == "/ground_truth"]
    truth_ns, truth_poses = np.array([t for t, _ in truth]), np.array([p for _, p in truth])
    first = next(np.array(_planar_odometry(r.msg)[1]) for r in raws if r.topic == "/odom")
    drifted, last, msgs = np.zeros(3), first, []
    for r in raws:
        if r.topic == "/ground_truth" or (r.topic == "/tf" and r.msg.transforms[0].child_frame_id == "base_link"):
            continue
        if r.topic != "/odom":
            msgs.append((r.topic, r.msgtype, r.log_time_ns, r.msg))
            continue
        t, pose = _planar_odometry(r.msg)
        step = relative(last, np.array(pose))
        last = np.array(pose)
        drifted = compose(drifted, step + np.array([0.0, 0.0, yaw_drift_per_m * float(np.hypot(*step[:2]))]))
        x, y, yaw = drifted
        msgs += [("/odom", r.msgtype, r.log_time_ns, m.odometry(t, "odom", "base_link", x, y, yaw)),
                 ("/tf", "tf2_msgs/msg/TFMessage", r.log_time_ns,
                  m.tf_message([m.planar_transform(t, "odom", "base_link", x, y, yaw)]))]
        at, ok = interpolate_poses(truth_ns, truth_poses, np.array([t])) if under_a_localizer else (None, [False])
        if ok[0]:
            assert at is not None
            cx, cy, cyaw = compose(at[0], inverse(np.array([x, y, yaw])))
            msgs.append(("/tf", "tf2_msgs/msg/TFMessage", r.log_time_ns,
                         m.tf_message([m.planar_transform(t, "map", "odom", cx, cy, cyaw)])))
    return write_messages(out, msgs)


def _planar_odometry(msg: Any) -> tuple[int, tuple[float, float, float]]:
    p = msg.pose.pose
    return (msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec,
            (p.position.x, p.position.y, 2 * float(np.arctan2(p.orientation.z, p.orientation.w))))


def test_passes_recorded_apart_without_a_localizer_can_be_joined_by_global_localization(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two sample passes, each its own recording with odometry from zero and nothing else to relate them (the
    second starts 37 m from where the first ended), their odometry turning 0.23° per metre too much: the second is
    placed on the first's map by MCL's global localization, and the doors come where matching the sample's scans
    in one continuous odometry frame puts them. (Placing the pass at the localized pose but predicting its first
    scan from the first pass's drifted odometry, the reviewer's case, lost 5 of the 7 doors.)"""
    from doorbatch.geometry.se2 import compose, inverse
    from doorbatch.io.recording import load_recording

    logs = [SAMPLE_LOGS / f"map_pass{k}.mcap" for k in (1, 2)]
    apart = [_recorded_apart(p, tmp_path / p.name, yaw_drift_per_m=0.004) for p in logs]
    assert main(["map", *map(str, apart), "-o", str(tmp_path / "refused"), "--stages", "grid"]) == 3
    assert "--set mapping.join_passes=true" in capsys.readouterr().err  # by default refused (issue #4), with the way
    assert main(["map", *map(str, apart), "-o", str(tmp_path / "joined"), "--stages", "grid", "--json", "--set",
                 "mapping.join_passes=true"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["pose_source"] == "scanmatch"
    assert any("placed on the map of the passes before it by global localization" in w for w in out["warnings"])
    assert main(["map", *map(str, logs), "-o", str(tmp_path / "one"), "--stages", "grid", "--pose-source",
                 "scanmatch", "-q"]) == 0
    rec = load_recording(logs[0], DoorbatchConfig())
    assert rec.odometry is not None
    start = inverse(rec.odometry.poses[0])  # the continuous frame seen from the first pass's start
    got = read_table("doors", tmp_path / "joined" / "doors.parquet").to_pydict()
    want = read_table("doors", tmp_path / "one" / "doors.parquet").to_pydict()
    hinges = np.column_stack([want["hinge_x"], want["hinge_y"], np.zeros(len(want["hinge_x"]))])
    hinges = compose(np.broadcast_to(start, hinges.shape), hinges)[:, :2]
    assert len(got["door_id"]) == len(want["door_id"]) >= 2
    for x, y in zip(got["hinge_x"], got["hinge_y"], strict=True):
        # the drift moves hinges by up to 0.11 m with one continuous odometry too (the reviewer's case: 32.82, 0.97)
        assert np.hypot(hinges[:, 0] - x, hinges[:, 1] - y).min() < 0.15


def test_a_pass_that_global_localization_cannot_place_is_refused(write_log: Callable[..., Path], tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """A second pass from somewhere else (a small log whose scans fit nowhere on the first pass's corridor map)
    with odometry that does not continue the first's: the map is refused with the reason, not laid across."""
    first = _recorded_apart(SAMPLE_LOGS / "map_pass1.mcap", tmp_path / "pass1.mcap")
    msgs = [x for x in sample_messages(40) if x[0] != "/ground_truth"]
    elsewhere = write_log("elsewhere.mcap", msgs)
    code = main(["map", str(first), str(elsewhere), "-o", str(tmp_path / "out"), "--stages", "grid", "--set",
                 "mapping.join_passes=true"])
    err = capsys.readouterr().err
    assert code == 3 and "disjoint coordinate frames" in err and "global localization" in err


def test_scan_matched_poses_go_into_the_frame_of_a_reference_that_repeats_the_odometry(
        write_log: Callable[..., Path]) -> None:
    """A simulator's perfect odometry beside its ground truth (here the truth is the odometry turned by 0.5 rad and
    moved by (3, −2) m): auto matches scans, and the poses it gets in the odometry's frame are moved by that rigid
    motion into the reference's, so that the map lies where the truth says. A raw CARMEN log (reference = odometry)
    is left as it is."""
    from doorbatch.geometry.se2 import interpolate_poses
    from doorbatch.io.recording import load_recording
    from doorbatch.pipeline.mapping import PassPoses, in_reference_frame

    config = DoorbatchConfig()
    rec = load_recording(write_log("perfect.mcap", _with_reference(_turned_and_moved)), config)
    assert rec.reference_is_odometry and rec.odometry is not None and rec.reference is not None
    stamps = rec.scans.stamps_ns
    odo, ok = interpolate_poses(rec.odometry.stamps_ns, rec.odometry.poses, stamps)
    matched = PassPoses(rec.path, stamps, odo, ok, "scanmatch")  # matching that kept the odometry
    (moved,), note = in_reference_frame([matched], [rec])
    ref, ref_ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, stamps)
    both = ok & ref_ok
    assert both.sum() >= 25
    np.testing.assert_allclose(moved.poses[both, :2], ref[both, :2], atol=1e-6)
    np.testing.assert_allclose(np.angle(np.exp(1j * (moved.poses[both, 2] - ref[both, 2]))), 0.0, atol=1e-6)
    assert note is not None and "(3.000 m, -2.000 m, 28.65°)" in note
    same = load_recording(write_log("raw.mcap", _with_reference(lambda x, y, yaw: (x, y, yaw))), config)
    assert same.reference_is_odometry
    (kept,), note = in_reference_frame([matched], [same])
    assert note is None and kept is matched


def test_the_reference_frame_is_the_first_repeating_pass_s_whatever_the_order(
        write_log: Callable[..., Path]) -> None:
    """Passes in one odometry frame, one with an independent reference (no motion to take) and one whose
    reference repeats the odometry turned and moved: the scan-matched poses go into the latter's frame in either
    order; and a sparse such reference (one pose every 0.7 s, gaps beyond mapping.max_pose_gap_s) gives the
    same motion as a dense one (the old check, with that gap limit, moved nothing)."""
    from dataclasses import replace

    from doorbatch.geometry.se2 import interpolate_poses
    from doorbatch.io.recording import load_recording
    from doorbatch.pipeline.mapping import PassPoses, in_reference_frame

    config = DoorbatchConfig()
    msgs = _with_reference(_turned_and_moved)
    truth = [t for topic, _, t, _ in msgs if topic == "/ground_truth"]
    sparse = [x for x in msgs if x[0] != "/ground_truth"]  # between scans, where the sample's motion is linear
    for k in range(0, 29, 7):
        sparse.append(("/ground_truth", "nav_msgs/msg/Odometry", (truth[k] + truth[k + 1]) // 2, m.odometry(
            (truth[k] + truth[k + 1]) // 2, "map", "base_link", *_turned_and_moved(0.1 * k + 0.05, 0.02 * k + 0.01,
                                                                                  0.01 * k + 0.005))))
    sparse.sort(key=lambda x: x[2])
    assert (truth[7] - truth[0]) / 1e9 > config.mapping.max_pose_gap_s
    repeating, thin = (load_recording(write_log(name, m), config) for name, m in
                       (("dense.mcap", msgs), ("sparse.mcap", sparse)))
    assert thin.odometry_to_reference is not None and repeating.odometry_to_reference is not None
    np.testing.assert_allclose(thin.odometry_to_reference, [3.0, -2.0, 0.5], atol=1e-6)
    independent = replace(repeating, odometry_to_reference=None)
    assert repeating.odometry is not None
    stamps = repeating.scans.stamps_ns
    odo, ok = interpolate_poses(repeating.odometry.stamps_ns, repeating.odometry.poses, stamps)
    matched = PassPoses(repeating.path, stamps, odo, ok, "scanmatch")
    for order in ([independent, repeating], [repeating, independent], [independent, thin]):
        moved, note = in_reference_frame([matched, matched], order)
        assert note is not None and "(3.000 m, -2.000 m, 28.65°)" in note
        want = _turned_and_moved(*odo[ok][0])
        np.testing.assert_allclose(moved[0].poses[ok][0], want, atol=1e-6)
        np.testing.assert_allclose(moved[1].poses, moved[0].poses)


def test_a_dropout_between_two_hits_clears_nothing_behind_the_wall(write_log: Callable[..., Path],
                                                                  tmp_path: Path) -> None:
    """A robot standing in a 4 m square room whose laser loses single echoes at random (+inf between two hits on the
    wall, and across the first beam of its full circle): with grid.dropout_max_beams 0 those beams clear 5 m,
    through the walls; by default no free cell lies outside the room."""
    from doorbatch.maps import FREE

    rng = np.random.default_rng(4)
    angles = np.deg2rad(np.arange(-180.0, 180.0, 1.0))
    wall = 2.0 / np.maximum(np.abs(np.cos(angles)), np.abs(np.sin(angles)))  # square of half-side 2 m
    msgs = [("/tf_static", "tf2_msgs/msg/TFMessage", T0,
             m.tf_message([m.planar_transform(T0, "base_link", "laser", 0.0, 0.0, 0.0)]))]
    for k in range(20):
        t = T0 + 100_000_000 * (k + 1)
        ranges = (wall + 0.005 * rng.standard_normal(angles.size)).astype(np.float32)
        ranges[rng.random(angles.size) < 0.03] = np.inf
        ranges[[1, -2]] = wall[[1, -2]]  # the last beam and the first lost too: one run of two across beam 0
        ranges[[0, -1]] = np.inf
        msgs += [("/odom", "nav_msgs/msg/Odometry", t, m.odometry(t, "odom", "base_link", 0.0, 0.0, 0.0)),
                 ("/ground_truth", "nav_msgs/msg/Odometry", t, m.odometry(t, "map", "base_link", 0.0, 0.0, 0.0)),
                 ("/scan", "sensor_msgs/msg/LaserScan", t,
                  m.laser_scan(t, "laser", float(angles[0]), float(np.deg2rad(1.0)), 0.05, 10.0, ranges))]
    log = write_log("room.mcap", msgs)

    def free_outside(out: Path, *sets: str) -> int:
        args = [a for kv in sets for a in ("--set", kv)]
        assert main(["map", str(log), "-o", str(out), "--stages", "grid", "--pose-source", "reference", "-q",
                     *args]) == 0
        occ = read_map(out / "map.yaml")
        xy = occ.cell_to_world(np.argwhere(occ.occupancy == FREE))
        return int((np.abs(xy).max(axis=1) > 2.2).sum())

    assert free_outside(tmp_path / "all", "grid.dropout_max_beams=0") > 0
    assert free_outside(tmp_path / "default") == 0


def test_an_odometry_restart_where_the_last_pass_ended_but_turned_does_not_continue_it(
        write_log: Callable[..., Path]) -> None:
    """A round trip back to the dock, then a recording whose odometry restarts at zero facing the other way: it
    starts where the previous pass ended, but 180° turned, in another frame (a reviewer's case: the corridor came
    out doubled). A pass that starts where and as the previous one ended continues it."""
    from dataclasses import replace

    from doorbatch.geometry.se2 import compose
    from doorbatch.io.recording import load_recording
    from doorbatch.pipeline.mapping import continues

    config = DoorbatchConfig()
    rec = load_recording(write_log("a.mcap", sample_messages(6)), config)
    assert rec.odometry is not None
    end = rec.odometry.poses[-1]
    for turn_deg, expected in ((0.0, True), (5.0, True), (180.0, False), (-20.0, False)):
        start = end + np.array([0.05, 0.0, np.radians(turn_deg)])
        poses = compose(np.broadcast_to(start, rec.odometry.poses.shape), rec.odometry.poses - rec.odometry.poses[0])
        nxt = replace(rec, odometry=replace(rec.odometry, poses=poses))
        assert continues(rec, nxt, config) is expected, turn_deg


def test_odometry_passes_apart_with_a_reference_are_told_to_use_it(write_log: Callable[..., Path], tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """Stage passes recorded apart, mapped with --pose-source odometry: the refusal asked for a reference pose
    topic, which the logs have. It now says so; logs without one are still asked for one."""
    from tests.conftest import sample_messages

    messages = sample_messages(30)
    for k, msg in enumerate(msg for topic, _, _, msg in messages if topic == "/ground_truth"):
        msg.pose.pose.position.x += 0.01 * k  # the odometry drifts from the truth: a reference of its own
    a = write_log("a.mcap", messages)
    b = write_log("b.mcap", messages)
    code = main(["map", str(a), str(b), "-o", str(tmp_path / "out"), "--pose-source", "odometry"])
    err = capsys.readouterr().err
    assert code == 3 and "disjoint coordinate frames" in err
    assert "the logs have a reference pose topic: --pose-source reference" in err
    bare = [msg for msg in sample_messages(30) if msg[0] != "/ground_truth"]
    code = main(["map", str(write_log("c.mcap", bare)), str(write_log("d.mcap", bare)), "-o", str(tmp_path / "o2"),
                 "--pose-source", "odometry"])
    err = capsys.readouterr().err
    assert code == 3 and "give a reference pose topic" in err


def test_a_map_killed_with_sigterm_unwinds_like_ctrl_c(tmp_path: Path) -> None:
    """SIGTERM (a cron job's timeout, a scheduler) killed `doorbatch map` outright (exit 143), past the cleanup that
    Ctrl-C runs; every command now takes it as Ctrl-C: exit 130, no output folder, no staged folder left."""
    import os
    import signal
    import subprocess
    import sys
    import time

    out = tmp_path / "map"
    cmd = [sys.executable, "-m", "doorbatch.cli", "map", *(str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)),
           "-o", str(out), "-q"]
    proc = subprocess.Popen(cmd, env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    time.sleep(4.0)  # reading and mapping the passes (about 30 s in all)
    assert proc.poll() is None
    proc.send_signal(signal.SIGTERM)
    # 130 from doorbatch's handler; rarely CPython re-raises the handled interrupt as SIGINT at exit (test_run_cli)
    assert proc.wait(60) in (130, -signal.SIGINT), proc.stderr.read() if proc.stderr else ""
    assert not out.exists() and not list(tmp_path.glob(".*"))


@pytest.mark.parametrize(("source", "told"), [("odometry", True), ("reference", False)])
def test_passes_whose_poses_disagree_with_the_map_are_told(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                           source: str, told: bool) -> None:
    """The sample mapped from its drifting odometry: 64-73 % of each pass's end points fall in cells the map holds
    free (3-6 % with the reference, 10-25 % in a crowd), and its doors are mostly not the world's; that had passed
    without a word (a worse odometry gave 28 doors, 27 false)."""
    logs = [str(SAMPLE_LOGS / f"map_pass{k}.mcap") for k in (1, 2, 3)]
    assert main(["map", *logs, "-o", str(tmp_path / "map"), "--pose-source", source, "--stages", "grid",
                 "--json"]) == 0
    warnings = [w for w in json.loads(capsys.readouterr().out)["warnings"] if "disagree with the map" in w]
    assert bool(warnings) == told
    if told:
        assert "--pose-source scanmatch" in warnings[0] and "map_pass3.mcap's" in warnings[0]


def test_the_manifests_read_stage_covers_reading_the_logs(write_log: Callable[..., Path], tmp_path: Path,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    # run_map reads the logs (with colours) before build_map, whose own 'read' then timed nothing (1e-6 s)
    import time

    import doorbatch.pipeline.map_run as map_run

    reading = map_run.mapping_passes

    def slow_reading(*args: Any, **kwargs: Any) -> Any:
        time.sleep(0.3)
        return reading(*args, **kwargs)

    monkeypatch.setattr(map_run, "mapping_passes", slow_reading)
    out = tmp_path / "map"
    assert main(["map", str(write_log("a.mcap")), "-o", str(out), "--stages", "grid", "-q"]) == 0
    assert json.loads((out / "manifest.json").read_text())["stage_seconds"]["read"] >= 0.3


def test_a_door_search_with_no_direction_to_try_maps_without_doors_there(tmp_path: Path) -> None:
    # doors.max_rotation_deg 1e-9 leaves a lone leaf's partner search no yaw to try: np.split of nothing gave one
    # empty run, indexed (IndexError, exit 1; hAP's config fuzzer on 10 s of each sample pass)
    from mcap.reader import make_reader

    from doorbatch.io.split import copy_window

    logs = []
    for k in (1, 2, 3):
        src = SAMPLE_LOGS / f"map_pass{k}.mcap"
        with src.open("rb") as f:
            summary = make_reader(f).get_summary()
        assert summary is not None and summary.statistics is not None
        t0 = summary.statistics.message_start_time
        logs.append(tmp_path / f"pass{k}.mcap")
        copy_window(src, logs[-1], t0, t0 + 10_000_000_000)
    out = tmp_path / "map"
    assert main(["map", *map(str, logs), "-o", str(out), "--stages", "grid", "-q",
                 "--set", "doors.max_rotation_deg=1e-9"]) == 0
    assert (out / "map.pgm").is_file()
