"""Bad input: each case gives its exit code and one line naming the file (and topic), no traceback."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import pytest

from doorbatch.cli import main
from doorbatch.io import ros_messages as m
from tests.conftest import REPO, sample_messages


def _run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str]:
    code = main(list(args))
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(lines) == 1, err
    return lines[0]


def test_zero_byte_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "empty.mcap"
    path.touch()
    code, err = _run(capsys, "inspect", str(path))
    assert code == 3
    assert str(path) in _one_line(err) and "empty" in err


def test_an_mcap_cut_off_before_its_first_message_is_an_error(write_log: Callable[..., Path], tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    whole = write_log("whole.mcap").read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[:200])  # the header and part of the first schema
    code, err = _run(capsys, "inspect", str(cut))
    assert code == 3
    assert str(cut) in _one_line(err) and "no readable message" in err


def test_an_mcap_whose_recording_was_cut_off_reads_up_to_the_cut(write_log: Callable[..., Path], tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    # a recorder killed mid-file leaves no summary section: the messages before the cut are read, with a warning
    whole = (REPO / "datasets" / "sample" / "logs" / "loc_open.mcap").read_bytes()  # chunks of ~1 s
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(whole[: len(whole) // 2])
    assert main(["inspect", str(cut), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    scans = next(t for t in report["topics"] if t["name"] == "/scan")
    assert 50 < scans["count"] < 400
    assert any("no summary section" in p["message"] for p in report["problems"])


@pytest.mark.parametrize("fmt", ["bag", "rosbag2"])
def test_a_damaged_bag_is_a_read_error_that_says_why(write_log: Callable[..., Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str], fmt: str) -> None:
    path = write_log(f"whole.{fmt}", fmt=fmt)
    if fmt == "bag":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    else:  # a ROS 2 bag folder whose metadata.yaml is junk
        (path / "metadata.yaml").write_text("rosbag2_bagfile_information: [1, 2\n")
    code, err = _run(capsys, "inspect", str(path))
    line = _one_line(err)
    assert code == 3 and str(path) in line and "internal error" not in line and "is not open" not in line
    if fmt == "bag":  # a recording cut short: the message names the tool that mends it
        assert "rosbag reindex" in line


def test_file_that_is_not_a_log(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "notes.txt"
    path.write_text("hello\n")
    code, err = _run(capsys, "inspect", str(path))
    assert code == 3
    assert str(path) in _one_line(err) and "supported" in err


def test_mcap_suffix_with_wrong_content(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "fake.mcap"
    path.write_bytes(b"PK\x03\x04 this is a zip")
    code, err = _run(capsys, "inspect", str(path))
    assert code == 3 and "magic" in _one_line(err)


def test_bag_with_no_laserscan(write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    path = write_log("noscan.bag", [m for m in sample_messages(3) if m[0] != "/scan"], fmt="bag")
    code, err = _run(capsys, "inspect", str(path))
    assert code == 3
    line = _one_line(err)
    assert str(path) in line and "LaserScan" in line


def test_scan_ranges_length_does_not_match_angles(write_log: Callable[..., Path],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    messages = sample_messages(3)
    for topic, _, _, msg in messages:
        if topic == "/scan":
            msg.angle_max = msg.angle_min + msg.angle_increment * (len(msg.ranges) + 9)
    path = write_log("mismatch.mcap", messages)
    code, err = _run(capsys, "inspect", str(path))
    assert code == 3
    line = _one_line(err)
    assert str(path) in line and "/scan" in line and "does not match" in line


def _problems(capsys: pytest.CaptureFixture[str], path: Path) -> list[dict[str, str]]:
    assert main(["inspect", str(path), "--json"]) == 0
    return list(json.loads(capsys.readouterr().out)["problems"])


def test_scan_stamps_going_backwards_are_a_warning_saying_they_are_sorted(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    messages = sample_messages(5)
    scans = [msg for topic, _, _, msg in messages if topic == "/scan"]
    scans[3].header.stamp, scans[2].header.stamp = scans[2].header.stamp, scans[3].header.stamp
    problems = _problems(capsys, write_log("backwards.bag", messages, fmt="bag"))
    assert any(p["topic"] == "/scan" and "backwards" in p["message"] and "sort them" in p["message"]
               and p["severity"] == "warning" for p in problems)


def test_unset_stamps_and_two_clocks_are_reported(write_log: Callable[..., Path],
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    messages = sample_messages(5)
    for k, msg in enumerate(msg for topic, _, _, msg in messages if topic == "/scan"):
        msg.header = m.header(10_000_000 * k, msg.header.frame_id)  # a device clock from 0
    device = write_log("device.mcap", messages)
    problems = _problems(capsys, device)
    assert not any("are 0" in p["message"] for p in problems)  # the first stamp is the clock's start, not unset
    assert any("different clocks" in p["message"] for p in problems)
    assert main(["inspect", str(device)]) == 0
    assert "Clock:      log times: the scan and odometry header stamps are on different clocks" in \
        capsys.readouterr().out
    for k, msg in enumerate(msg for topic, _, _, msg in messages if topic == "/scan"):
        msg.header = m.header(5 * 10**9 + 10_000_000 * k if k else 0, msg.header.frame_id)  # the first one unset
    problems = _problems(capsys, write_log("unset.mcap", messages))
    assert any(p["topic"] == "/scan" and "1 of 5 header stamps are 0" in p["message"] for p in problems)
    assert not any("clock" in p["message"] for p in _problems(capsys, write_log("fine.mcap", sample_messages(5))))
    tf_only = [msg for msg in messages if msg[0] != "/odom"]  # odometry from TF odom → base_link only
    assert any("different clocks" in p["message"] for p in _problems(capsys, write_log("tf.mcap", tf_only)))


def test_scans_whose_times_are_lost_are_refused_not_drawn_at_one_pose(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """A CARMEN log converted with its ipc_timestamp (0 throughout in orebro): header stamps and log times all 0.
    Mapped, every scan had been drawn at one pose (138 occupied cells for 13,521), localized in one update, exit
    0; inspect said the log time stands in. Both now say the scans' times are lost (exit 3 where they are needed)."""
    messages = [(topic, kind, 0, msg) for topic, kind, _, msg in sample_messages(12)]
    for *_, msg in messages:
        if hasattr(msg, "header"):
            msg.header = m.header(0, msg.header.frame_id)
    path = write_log("timeless.mcap", messages)
    assert main(["inspect", str(path)]) == 3
    assert "error   /scan: 12 scans carry only 1 distinct stamp(s)" in capsys.readouterr().out
    code, err = _run(capsys, "map", str(path), "-o", str(path.parent / "map"))
    assert code == 3 and "their times are lost" in _one_line(err)


def test_inspect_describes_the_laser_and_warns_of_a_narrow_one(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """A depth camera as the laser (58°, 5 m): inspect said "Problems: none", though doors were then missed and
    global localization failed. It now prints the laser (beams, field of view, ranges) and warns of a narrow one."""
    messages = sample_messages(5)
    assert main(["inspect", str(write_log("wide.mcap", messages))]) == 0
    out = capsys.readouterr().out
    assert "Laser:      /scan: 181 beams over" in out and "field of view" not in out
    for topic, _, _, msg in messages:
        if topic == "/scan":
            msg.angle_increment = math.radians(58.0) / len(msg.ranges)
            msg.angle_min = -math.radians(29.0)
            msg.angle_max = msg.angle_min + msg.angle_increment * (len(msg.ranges) - 1)
    assert main(["inspect", str(write_log("narrow.mcap", messages))]) == 0
    out = capsys.readouterr().out
    assert "181 beams over 58.0°" in out and "warning /scan: a field of view of 58°" in out


@pytest.mark.parametrize(("sweep_s", "says"), [(0.09, "sweeps 90 ms (deskewed with the odometry)"),
                                              (0.3, "warning /scan: time_increment × beams is 300 ms, longer than")])
def test_inspect_tells_the_lasers_sweep_and_whether_it_is_deskewed(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str], sweep_s: float, says: str) -> None:
    """A rotating laser's sweep (time_increment) was told by map and localize only; inspect said "Problems: none"
    even for a time_increment × beams of 0.3 s on a 10 Hz laser, which is not deskewed."""
    messages = sample_messages(5)
    for topic, _, _, msg in messages:
        if topic == "/scan":
            msg.time_increment = sweep_s / (len(msg.ranges) - 1)
    assert main(["inspect", str(write_log("swept.mcap", messages))]) == 0
    assert says in capsys.readouterr().out


def test_inspect_warns_of_beams_that_hit_the_robots_own_body(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """A laser that sees the robot's posts (a run of beams at 0.12-0.2 m in every scan): inspect said "Problems:
    none". It now names the beams and the setting that leaves them out; a log whose near returns come and go
    (the robot passing close by things) is not warned of."""
    import numpy as np

    messages = sample_messages(20)
    rng = np.random.default_rng(3)
    for k, (topic, _, _, msg) in enumerate(messages):
        if topic == "/scan":
            ranges = np.asarray(msg.ranges, np.float32)
            ranges[30:34] = rng.uniform(0.12, 0.2, 4)  # a post, every scan
            ranges[100:103] = 0.2 if k % 3 else 5.0  # a near wall two scans in three: passed by, not the body
            msg.ranges = ranges
    assert main(["inspect", str(write_log("posts.mcap", messages))]) == 0
    problems = [line for line in capsys.readouterr().out.splitlines() if "own body" in line]
    assert len(problems) == 1
    assert "beams 30–33 (" in problems[0] and "4 of 181" in problems[0] and "100–102" not in problems[0]
    assert "localize.laser_min_range=0.3" in problems[0]
    for _, _, _, msg in (m_ for m_ in messages if m_[0] == "/scan"):  # a full turn, a mast behind it across beam 0
        msg.angle_min, msg.angle_increment = -math.pi, 2 * math.pi / 181
        msg.angle_max = msg.angle_min + msg.angle_increment * 180
        ranges = np.asarray(msg.ranges, np.float32)
        ranges[30:34] = 5.0
        ranges[[179, 180, 0, 1]] = 0.15
        msg.ranges = ranges
    assert main(["inspect", str(write_log("mast.mcap", messages))]) == 0
    (mast,) = [line for line in capsys.readouterr().out.splitlines() if "own body" in line]
    assert "beams 179–1 (" in mast and "4 of 181" in mast


def test_unknown_config_key_names_the_closest(write_log: Callable[..., Path],
                                              capsys: pytest.CaptureFixture[str]) -> None:
    code, err = _run(capsys, "inspect", str(write_log("ok.mcap")), "--set", "io.gap_factr=3")
    assert code == 2
    line = _one_line(err)
    assert "io.gap_factr" in line and "io.gap_factor" in line


def test_unknown_key_in_config_file(tmp_path: Path, write_log: Callable[..., Path],
                                    capsys: pytest.CaptureFixture[str]) -> None:
    cfg = tmp_path / "c.yaml"
    cfg.write_text("grid:\n  resolution: 0.1\n")
    code, err = _run(capsys, "inspect", str(write_log("ok.mcap")), "--config", str(cfg))
    assert code == 2
    assert str(cfg) in _one_line(err) and "grid.resolution_m" in err


def test_a_good_log_inspects_cleanly(write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    import json

    code = main(["inspect", str(write_log("ok.mcap")), "--json"])
    out = capsys.readouterr().out
    assert code == 0
    report = json.loads(out)
    roles = {t["name"]: t["role"] for t in report["topics"]}
    assert roles["/scan"] == "scan" and roles["/odom"] == "odometry" and roles["/ground_truth"] == "reference"
    assert report["problems"] == []


def test_inspect_names_what_an_unused_map_or_initial_pose_can_be_given_as(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from doorbatch.io import ros_messages
    from tests.conftest import sample_messages

    t0 = sample_messages()[0][2]
    extra = [("/map", "nav_msgs/msg/OccupancyGrid", t0,
              ros_messages.occupancy_grid(t0, "map", np.zeros((3, 3), dtype=np.int8), 0.05, 0.0, 0.0)),
             ("/initialpose", "geometry_msgs/msg/PoseWithCovarianceStamped", t0,
              ros_messages.pose_with_covariance_stamped(t0, "map", 1.0, 2.0, 0.0, np.eye(6)))]
    code = main(["inspect", str(write_log("nav2.mcap", [*sample_messages(), *extra]))])
    out = capsys.readouterr().out
    assert code == 0
    assert "unused (a map: localize --map LOG)" in out
    assert "unused (a start pose: localize --init /initialpose)" in out


def test_a_second_laser_and_an_ekfs_odometry_are_named_not_dropped_silently(
        write_log: Callable[..., Path], capsys: pytest.CaptureFixture[str]) -> None:
    """Two lasers: the one read and the one not are a problem inspect lists, and a warning every run carries; an
    unused Odometry topic (an EKF's) is offered as odometry, not as a start pose in the map."""
    from doorbatch.config import DoorbatchConfig
    from doorbatch.io.recording import load_recording
    from tests.conftest import sample_messages

    messages = sample_messages()
    extra = [("/scan_rear" if t == "/scan" else "/odometry/filtered", kind, at, msg)
             for t, kind, at, msg in messages if t in ("/scan", "/odom")]
    log_path = write_log("two_lasers.mcap", sorted([*messages, *extra], key=lambda m: m[2]))
    assert main(["inspect", str(log_path)]) == 0
    out = capsys.readouterr().out
    assert "2 laser scan topics: /scan is read" in out and "/scan_rear not" in out
    assert "unused (odometry or a reference: --set topics.odometry=/odometry/filtered" in out
    rec = load_recording(log_path, DoorbatchConfig())
    assert any("/scan_rear not" in w for w in rec.warnings)
    # a run says which odometry it reads, beside an EKF's (a skid-steer base's wheel odometry is poor in rotation)
    assert any("2 odometry topics: /odom is read" in w and "/odometry/filtered not" in w for w in rec.warnings)
    chosen = load_recording(log_path, DoorbatchConfig.model_validate(
        {"topics": {"scan": "/scan_rear", "odometry": "/odometry/filtered"}}))
    assert not any("laser scan topics" in w or "odometry topics" in w for w in chosen.warnings)  # the user's choice
    # a second truth topic of Odometry type (a log recorded twice, once under /robot) is no odometry to offer
    twice = [*messages, *(("/robot" + t, kind, at, msg) for t, kind, at, msg in messages if t == "/ground_truth")]
    truth = load_recording(write_log("twice.mcap", sorted(twice, key=lambda m: m[2])), DoorbatchConfig())
    assert not any("odometry topics" in w for w in truth.warnings)


def test_inspect_says_which_clock_the_scans_are_timed_by(write_log: Callable[..., Path],
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """A simulated run recorded on wall-clock time: header stamps in sim time from 300 s, running at 0.8 of the
    recording's pace; the rates inspect prints are the recorder's, and the Clock line says so."""
    import numpy as np

    from doorbatch.io.inspect import clock_line
    from tests.conftest import sample_messages

    assert main(["inspect", str(write_log("same.mcap", sample_messages()))]) == 0
    assert "Clock:      scan header stamps, on the recorder's clock" in capsys.readouterr().out
    sim = np.int64(300_000_000_000) + np.arange(50, dtype=np.int64) * 80_000_000
    wall = np.int64(1_700_000_000_000_000_000) + np.arange(50, dtype=np.int64) * 100_000_000
    line = clock_line(sim, wall, 0.5)
    assert "another clock" in line and "from 300.000 s" in line and "advancing 0.80 s per recorded second" in line
    # a driver that never fills its stamps: not "another clock from 0.000 s, advancing 0.00 s" (a helper's log)
    unset = clock_line(np.zeros(50, dtype=np.int64), wall, 0.5)
    assert unset == "log times: every scan header stamp is unset (Problems)"
    sim[:10] = 0  # some unset: the rest tell the clock
    assert "from 300.800 s" in clock_line(sim, wall, 0.5)


def test_a_bag_folder_without_metadata_names_its_mcap(write_log: Callable[..., Path], tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "rosbag2_2026_11_26"
    folder.mkdir()
    mcap = write_log("rosbag2_2026_11_26_0.mcap").rename(folder / "rosbag2_2026_11_26_0.mcap")
    code, err = _run(capsys, "inspect", str(folder))
    assert code == 3 and "no metadata.yaml" in _one_line(err) and str(mcap) in err
    assert main(["inspect", str(mcap)]) == 0


def test_a_sqlite_bag_without_metadata_or_given_by_its_file_says_what_to_give(
        write_log: Callable[..., Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A ROS 2 bag's .db3 given as the log, and a killed sqlite3 recording (no metadata.yaml): each message says
    what to do (the folder; ``ros2 bag reindex``), where they had said only "not a log doorbatch can read" and
    "folder is not a ROS 2 bag" (hAL)."""
    bag = write_log("bag", fmt="rosbag2")
    db3 = next(bag.glob("*.db3"))
    code, err = _run(capsys, "inspect", str(db3))
    assert code == 3 and "give the bag's folder" in _one_line(err) and str(bag) in err
    (bag / "metadata.yaml").unlink()
    code, err = _run(capsys, "inspect", str(bag))
    assert code == 3 and "no metadata.yaml" in _one_line(err) and "ros2 bag reindex" in err


_OUTPUT_COMMANDS = [
    ["map", str(REPO / "datasets/sample/logs/map_pass1.mcap"), "--stages", "grid"],
    ["convert", str(REPO / "datasets/sample/logs/map_pass1.mcap")],
]


def _target(command: list[str], folder: Path) -> Path:
    return folder / ("x.mcap" if command[0] == "convert" else "x")


@pytest.mark.parametrize("command", _OUTPUT_COMMANDS)
def test_an_output_under_a_file_is_a_usage_error_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                                 command: list[str]) -> None:
    blocker = tmp_path / "afile"
    blocker.write_text("")
    code, err = _run(capsys, *command, "-o", str(_target(command, blocker)))
    assert code == 2 and f"{blocker} is a file" in _one_line(err)


@pytest.mark.parametrize("command", _OUTPUT_COMMANDS)
def test_an_output_in_a_read_only_folder_is_a_usage_error_before_any_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: list[str]) -> None:
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        try:
            (locked / "probe").mkdir()
            pytest.skip("this user writes in read-only folders (root)")
        except PermissionError:
            pass
        code, err = _run(capsys, *command, "-o", str(_target(command, locked)))
        assert code == 2 and f"cannot write in {locked}" in _one_line(err)
    finally:
        locked.chmod(0o700)


def test_a_few_malformed_scans_are_skipped_with_a_warning(write_log: Callable[..., Path], tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """DESIGN: a warning and a skip where the rest is usable (here 2 of 12 scans); most bad stays an error."""
    messages = sample_messages(12)
    for k, msg in enumerate(msg for topic, _, _, msg in messages if topic == "/scan"):
        if k in (4, 7):
            msg.angle_max = msg.angle_min + msg.angle_increment * (len(msg.ranges) + 9)
    path = write_log("two_bad.mcap", messages)
    assert any("2 of 12 scans are unusable" in p["message"] for p in _problems(capsys, path))
    code, err = _run(capsys, "map", str(path), "-o", str(tmp_path / "map"), "--stages", "grid", "--json")
    assert code == 0 and "2 of 12 messages on /scan skipped" in err


def test_an_output_file_where_a_folder_stands_is_refused_and_the_folder_kept(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "d.mcap"
    folder.mkdir()
    (folder / "notes.txt").write_text("precious")
    code, err = _run(capsys, "convert", str(REPO / "datasets/sample/logs/map_pass1.mcap"), "-o", str(folder))
    assert code == 2 and "is a folder" in _one_line(err)
    assert (folder / "notes.txt").read_text() == "precious"


def test_checking_an_output_creates_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The -o check runs before the config is read: when the command then fails, no folder is left behind."""
    code, _ = _run(capsys, "map", str(REPO / "datasets/sample/logs/map_pass1.mcap"), "-o",
                   str(tmp_path / "a" / "b" / "map"), "--set", "mapping.bogus=1")
    assert code == 2 and not (tmp_path / "a").exists() and list(tmp_path.iterdir()) == []



def test_a_message_that_does_not_decode_names_its_own_topic(write_log: Callable[..., Path],
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """A rosbag2 folder whose /detections payloads do not fit the definition: the error names /detections, not
    the topic of the message read before it."""
    import sqlite3

    bag = write_log("bad.rosbag2", fmt="rosbag2")
    (db,) = bag.glob("*.db3")
    with sqlite3.connect(db) as con:
        con.execute("UPDATE messages SET data = x'000100' WHERE topic_id = "
                    "(SELECT id FROM topics WHERE name = '/detections')")
    code, err = _run(capsys, "inspect", str(bag))
    assert code == 3 and "topic /detections" in _one_line(err)


def test_a_topic_override_the_log_lacks_names_the_file_and_the_closest_topic(write_log: Callable[..., Path],
                                                                             capsys: pytest.CaptureFixture[str]
                                                                             ) -> None:
    path = write_log("ok.mcap")
    code, err = _run(capsys, "inspect", str(path), "--set", "topics.scan=/scann")
    line = _one_line(err)
    assert code == 3 and str(path) in line and "/scann" in line and "did you mean /scan?" in line
    code, err = _run(capsys, "inspect", str(path), "--set", "topics.detections=/boxes")
    assert code == 3 and "/detections" in _one_line(err)


def test_inspect_says_where_the_odometry_comes_from(write_log: Callable[..., Path],
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    messages = sample_messages(5)
    for name, msgs, expected in (("topic.mcap", messages, "/odom (nav_msgs/Odometry)"),
                                 ("tf.mcap", [x for x in messages if x[0] != "/odom"], "TF odom→base_link")):
        path = write_log(name, msgs)
        assert main(["inspect", str(path), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["odometry"] == expected
        assert main(["inspect", str(path)]) == 0
        assert f"Odometry:   {expected}" in capsys.readouterr().out


def test_inspect_says_where_the_reference_comes_from(write_log: Callable[..., Path],
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """A reference topic; else a localizer's moving map → odom on /tf; else none."""
    from doorbatch.io import ros_messages as m

    messages = sample_messages(5)
    no_truth = [x for x in messages if x[0] != "/ground_truth"]
    scan_times = [x[2] for x in no_truth if x[0] == "/scan"]
    localized = [*no_truth, *(("/tf", "tf2_msgs/msg/TFMessage", t, m.tf_message([m.planar_transform(
        t, "map", "odom", 1.0 + 0.01 * k, 0.0, 0.1)])) for k, t in enumerate(scan_times))]
    for name, msgs, expected in (("truth.mcap", messages, "/ground_truth (nav_msgs/Odometry)"),
                                 ("amcl.mcap", sorted(localized, key=lambda x: x[2]),
                                  "TF map→base_link (a localizer's or SLAM's moving map→odom)"),
                                 ("none.mcap", no_truth, "none")):
        path = write_log(name, msgs)
        assert main(["inspect", str(path), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["reference"] == expected


def test_running_out_of_memory_is_one_line_that_names_the_likely_config_values(
        write_log: Callable[..., Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    # hAP's config fuzzer: grid.growth_margin_m=1e9 asked numpy for 29 TiB, reported as an "internal error"
    import doorbatch.cli as cli_module
    import doorbatch.pipeline.map_run as map_run

    def too_big(*_: object, **__: object) -> None:
        raise MemoryError("Unable to allocate 29.1 TiB for an array with shape (400, 20000000575)")

    monkeypatch.setattr(map_run, "build_map", too_big)
    monkeypatch.setattr(cli_module, "CRASH_LOG", tmp_path / "crash.log")
    assert main(["map", str(write_log("a.mcap")), "-o", str(tmp_path / "map"), "--stages", "grid", "-q"]) == 1
    line = capsys.readouterr().err.strip().splitlines()[-1]
    assert line.startswith("error: out of memory (Unable to allocate 29.1 TiB") and "grid resolution" in line
    assert "internal error" not in line and "MemoryError" in (tmp_path / "crash.log").read_text()


@pytest.mark.parametrize("rate", ["1e-9", "1e9"])
def test_a_controller_rate_no_robot_runs_is_a_config_error(rate: str) -> None:
    from doorbatch.config import load_config
    from doorbatch.errors import ConfigError

    with pytest.raises(ConfigError, match="control_rate_hz"):
        load_config(overrides=[f"doorpose.control_rate_hz={rate}"])
