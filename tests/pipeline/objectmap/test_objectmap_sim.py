"""The em stage end to end on a tiny simulated site with ground truth: a 9 m corridor, one door that moves
between passes and one that never moves (painted like the moving one), three passes with colours."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig
from doorbatch.io.object_map import read_classes, read_walls, write_classes
from doorbatch.io.parquet import read_table
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.mapping import pass_poses
from doorbatch.pipeline.objectmap.beams import beams_from_scans
from doorbatch.pipeline.objectmap.model import ClassParams
from doorbatch.pipeline.objectmap.stage import (
    ObjectMapResult,
    build_object_map,
    collect_beams,
    final_step_beams,
    pass_scans,
)
from doorbatch.sim.simulate import run_simulation

WORLD = """
name: tiny_em
materials:
  wall: {mean_rgb: [196, 192, 182], std_rgb: [7, 7, 7]}
  door: {mean_rgb: [158, 122, 92], std_rgb: [14, 14, 14]}
  handle: {mean_rgb: [48, 48, 52], std_rgb: [3, 3, 3]}
walls:
  - {points_m: [[0.0, 1.1], [9.0, 1.1]]}
  - {points_m: [[0.0, -1.1], [9.0, -1.1]]}
  - {points_m: [[0.0, -1.1], [0.0, 1.1]]}
  - {points_m: [[9.0, -1.1], [9.0, 1.1]]}
rooms:
  - {points_m: [[1.0, 1.1], [1.0, 2.8], [8.0, 2.8], [8.0, 1.1]]}
  - {points_m: [[1.0, -1.1], [1.0, -2.8], [8.0, -2.8], [8.0, -1.1]]}
doors:
  - {name: d01, hinge_m: [3.0, 1.1], length_m: 0.9, closed_yaw_deg: 0, opening_sign: 1, max_angle_deg: 100}
  - {name: d02, hinge_m: [5.5, -1.1], length_m: 0.9, closed_yaw_deg: 0, opening_sign: -1, max_angle_deg: 100}
routes:
  main: {points_m: [[1.0, 0.0], [8.0, 0.0]]}
"""
SCENARIO = """
name: tiny_em_mapping
robot: {max_speed_mps: 0.7}
passes:
  - {name: p1, route: main, dwell_s: 0.5, doors: closed, door_states: {d01: open}}
  - {name: p2, route: main, reverse: true, dwell_s: 0.5, doors: closed}
  - {name: p3, route: main, dwell_s: 0.5, doors: closed, door_states: {d01: partial}}
sensors:
  laser: {rate_hz: 10, fov_deg: 270, beams: 360, max_range_m: 15.0, sigma_m: 0.01}
  odometry: {rate_hz: 10}
  ground_truth: {rate_hz: 10}
  camera: {enabled: false}
  detections: {enabled: false}
"""


@pytest.fixture(scope="module")
def tiny_site(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("tiny_em")
    (folder / "world.yaml").write_text(WORLD)
    (folder / "scenario.yaml").write_text(SCENARIO)
    run_simulation(folder / "world.yaml", folder / "map.mcap", scenario=str(folder / "scenario.yaml"), seed=3,
                   split_passes=True)
    return sorted(folder.glob("map_pass*.mcap"))


@pytest.fixture(scope="module")
def short_range_site(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """The tiny site seen by a TurtleBot-like laser: 360°, 3.5 m, 5 Hz, σ 1.5 cm."""
    folder = tmp_path_factory.mktemp("tiny_em_short")
    (folder / "world.yaml").write_text(WORLD)
    (folder / "scenario.yaml").write_text(SCENARIO.replace(
        "laser: {rate_hz: 10, fov_deg: 270, beams: 360, max_range_m: 15.0, sigma_m: 0.01}",
        "laser: {rate_hz: 5, fov_deg: 360, beams: 360, max_range_m: 3.5, sigma_m: 0.015}"))
    run_simulation(folder / "world.yaml", folder / "map.mcap", scenario=str(folder / "scenario.yaml"), seed=3,
                   split_passes=True)
    return sorted(folder.glob("map_pass*.mcap"))


def _em(logs: list[Path], classes: ClassParams | None = None, progress: Callable[[int], object] | None = None,
        **em: object) -> ObjectMapResult:
    config = DoorbatchConfig.model_validate({"em": {"scan_stride": 1, "beam_stride": 1, **em}})
    recs = [load_recording(p, config, with_colors=True) for p in logs]
    passes = [pass_poses(r, "reference", config) for r in recs]
    beams = collect_beams(recs, passes, config.em)
    final = final_step_beams(recs, passes, config.em) if progress is not None else None
    return build_object_map(beams, config.em, classes, final, progress=progress)


def test_the_em_stage_reports_each_iteration_and_final_sweep(tiny_site: list[Path]) -> None:
    """A long em stage showed nothing for minutes: a progress bar now advances by every EM iteration and every
    sweep of the final wall step."""
    steps: list[int] = []
    result = _em(tiny_site, progress=steps.append, use_color=False)
    assert len(steps) > len(result.trace.seconds) >= 2 and set(steps) == {1}


@pytest.fixture(scope="module")
def learned(tiny_site: list[Path]) -> ObjectMapResult:
    return _em(tiny_site)


def test_moved_door_hinge_angles_and_width_are_recovered(learned: ObjectMapResult) -> None:
    moved = [d for d in learned.doors if d.preview.moved]
    assert len(moved) == 1
    door = moved[0].preview
    assert np.hypot(door.hinge_x - 3.0, door.hinge_y - 1.1) < 0.05
    assert abs(door.length - 0.9) < 0.05
    np.testing.assert_allclose(np.rad2deg(moved[0].pass_yaws), [100.0, 0.0, 50.0], atol=3.0)
    assert abs(np.rad2deg(door.closed_yaw)) < 1.0


def test_never_moved_door_is_found_by_its_learned_colour(learned: ObjectMapResult) -> None:
    still = [d.preview for d in learned.doors if not d.preview.moved]
    assert len(still) == 1  # and nothing else: no false positive
    centre = np.array([still[0].hinge_x, still[0].hinge_y]) + 0.45 * np.array(
        [np.cos(still[0].closed_yaw), np.sin(still[0].closed_yaw)])
    assert np.linalg.norm(centre - [5.95, -1.1]) < 0.1
    mean = learned.object_map.classes.color_mean
    wall_rgb, door_rgb = np.array([196, 192, 182]), np.array([158, 122, 92])
    apart = np.linalg.norm(wall_rgb - door_rgb)  # the simulated lighting scales colours by up to ±12 %
    assert np.linalg.norm(mean[1] - door_rgb) < 0.3 * apart and np.linalg.norm(mean[0] - wall_rgb) < 0.3 * apart


def test_corridor_walls_are_straight_and_where_they_should_be(learned: ObjectMapResult) -> None:
    long_walls = [w for w in learned.object_map.walls if w.length > 3.0]
    offsets = sorted(abs(w.offset) for w in long_walls if abs(w.normal[1]) > 0.99)
    assert len(offsets) >= 2 and abs(offsets[0] - 1.1) < 0.02
    for w in long_walls:
        assert min(abs(w.normal[0]), abs(w.normal[1])) < np.sin(np.deg2rad(1.0))


def test_range_only_finds_the_moved_door_only(tiny_site: list[Path]) -> None:
    result = _em(tiny_site, use_color=False)
    assert [d.preview.moved for d in result.doors] == [True]


def test_learned_classes_find_the_still_door_without_relearning(tiny_site: list[Path], learned: ObjectMapResult,
                                                               tmp_path: Path) -> None:
    write_classes(tmp_path / "classes.json", learned.object_map.classes)
    given = read_classes(tmp_path / "classes.json")
    result = _em(tiny_site[1:2], classes=given)  # pass 2 alone: both doors closed, colour and width alone
    assert result.object_map.classes.door_width_m == pytest.approx(learned.object_map.classes.door_width_m)
    centres = sorted((round(d.preview.hinge_x + 0.45 * np.cos(d.preview.closed_yaw), 1), round(d.preview.hinge_y, 1))
                     for d in result.doors)
    assert centres == [(3.5, 1.1), (5.9, -1.1)] or centres == [(3.4, 1.1), (5.9, -1.1)]
    assert not any(d.preview.moved for d in result.doors)


def test_map_cli_writes_the_em_outputs_and_applies_classes(tiny_site: list[Path], tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "map"
    logs = [str(p) for p in tiny_site]
    sets = ["--set", "em.scan_stride=1", "--set", "em.beam_stride=1"]
    assert main(["map", *logs, "-o", str(out), *sets, "--json"]) == 0  # colours: em runs by default
    summary = json.loads(capsys.readouterr().out)
    doors = read_table("doors", out / "doors.parquet").to_pydict()
    assert set(doors["source"]) == {"em"} and len(doors["door_id"]) == summary["doors"] == 2
    assert sorted(doors["moved"]) == [False, True]
    walls = read_walls(out / "walls.parquet")
    assert sum(w.segments.shape[0] for w in walls) == len(read_table("walls", out / "walls.parquet"))
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["extra"]["stages"] == ["grid", "em"] and manifest["extra"]["em"]["doors"] == 2
    em = manifest["extra"]["em"]
    assert em["final_beams"] >= em["beams"] > 0 and em["final_scan_thinning"] == 1
    assert (em["final_scan_stride"], em["final_beam_stride"]) == (1, 1)  # a 360-beam 10 Hz laser: every beam
    assert not any("final wall step" in w for w in manifest["warnings"])
    out2 = tmp_path / "map2"
    assert main(["map", logs[1], "-o", str(out2), "--classes", str(out / "classes.json"), *sets, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["doors"] == 2  # pass 2: both doors closed, found by colour
    out4 = tmp_path / "map4"  # a beam budget for the final step: the manifest says what was left out
    assert main(["map", logs[1], "-o", str(out4), "--classes", str(out / "classes.json"), *sets,
                 "--set", "em.final_max_beams=20000", "-q"]) == 0
    thinned = json.loads((out4 / "manifest.json").read_text())
    assert thinned["extra"]["em"]["final_scan_thinning"] > 1 and thinned["extra"]["em"]["final_beams"] <= 20000
    assert any("final wall step kept 1 scan in" in w for w in thinned["warnings"])
    assert not any("has colour classes" in w for w in thinned["warnings"])
    out5 = tmp_path / "map5"  # colour classes on a log read without colours: said, not dropped in silence
    assert main(["map", logs[1], "-o", str(out5), "--classes", str(out / "classes.json"), *sets,
                 "--set", "em.use_color=false", "-q"]) == 0
    colourless = json.loads((out5 / "manifest.json").read_text())["warnings"]
    assert any("has colour classes, but em.use_color is off: its widths only were applied" in w for w in colourless)
    bad = tmp_path / "bad.json"
    bad.write_text("{}")
    assert main(["map", logs[1], "-o", str(tmp_path / "m3"), "--classes", str(bad)]) == 3
    assert "classes" in capsys.readouterr().err


def test_a_door_the_em_prior_does_not_pay_for_is_kept_from_the_grid_stage(tiny_site: list[Path], tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """A laser that puts few beams on each leaf (short range, low rate) gives a door less evidence than the em
    prior's fixed cost per door; here the cost is raised instead (ρD per pass angle), so the em stage keeps no
    door. The grid stage saw d01 swing about its hinge: doors.parquet lists it, source grid (and no door with
    em.keep_grid_doors=false)."""
    sets = ["--set", "em.scan_stride=1", "--set", "em.beam_stride=1", "--set", "em.rho_dynamic=100000"]
    logs = [str(p) for p in tiny_site]
    assert main(["map", *logs, "-o", str(tmp_path / "kept"), *sets, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    doors = read_table("doors", tmp_path / "kept" / "doors.parquet").to_pydict()
    assert doors["source"] == ["grid"] and summary["doors"] == 1 and doors["moved"] == [True]
    assert np.hypot(doors["hinge_x"][0] - 3.0, doors["hinge_y"][0] - 1.1) < 0.1
    manifest = json.loads((tmp_path / "kept" / "manifest.json").read_text())["extra"]["em"]
    assert manifest["doors"] == 0 and manifest["grid_doors_kept"] == 1
    assert main(["map", *logs, "-o", str(tmp_path / "em_only"), *sets, "--set", "em.keep_grid_doors=false",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["doors"] == 0


def _doors_of_map(logs: list[Path], out: Path, *sets: str) -> dict[str, list[object]]:
    assert main(["map", *map(str, logs), "-o", str(out), "-q", *(a for k in sets for a in ("--set", k))]) == 0
    return read_table("doors", out / "doors.parquet").to_pydict()


def test_with_a_short_range_laser_the_grid_doors_seed_the_em_search(short_range_site: list[Path],
                                                                     tmp_path: Path) -> None:
    """A 3.5 m laser puts few beams on d01: alone, the em search adopts no door (the first door also pays the
    width and the door colours, and its colour is not learned yet). Seeded with the grid stage's door (found by
    its motion) the em stage keeps it, fits its hinge and per-pass angles (100°, 0°, 50°) and learns its class;
    without the seed, doors.parquet still lists the grid stage's door."""
    alone = _doors_of_map(short_range_site, tmp_path / "alone", "em.seed_grid_doors=false",
                          "em.keep_grid_doors=false")
    assert alone["door_id"] == []
    kept = _doors_of_map(short_range_site, tmp_path / "kept", "em.seed_grid_doors=false")
    assert kept["source"] == ["grid"] and kept["moved"] == [True]
    seeded = _doors_of_map(short_range_site, tmp_path / "seeded", "em.seed_grid_doors=true",
                           "em.keep_grid_doors=false")
    assert seeded["source"] == ["em"] and seeded["moved"] == [True]
    assert np.hypot(seeded["hinge_x"][0] - 3.0, seeded["hinge_y"][0] - 1.1) < 0.05
    assert abs(seeded["length"][0] - 0.9) < 0.05
    assert abs(np.rad2deg(seeded["angle_max"][0]) - 100.0) < 3.0 and abs(seeded["angle_min"][0]) < np.deg2rad(3.0)


def test_a_standing_robot_gives_the_em_stage_one_scan_a_second(tmp_path: Path) -> None:
    """Scans of a robot standing still (a 3 s wait before the pass, 2 s after) are kept once per still_interval_s;
    every scan of a moving robot is kept."""
    (tmp_path / "world.yaml").write_text(WORLD)
    (tmp_path / "scenario.yaml").write_text(SCENARIO.replace("dwell_s: 0.5, doors: closed, door_states: {d01: open}",
                                                             "dwell_s: 3.0, end_dwell_s: 2.0, doors: closed"))
    run_simulation(tmp_path / "world.yaml", tmp_path / "map.mcap", scenario=str(tmp_path / "scenario.yaml"), seed=3,
                   split_passes=True)
    config = DoorbatchConfig()
    rec = load_recording(tmp_path / "map_pass1.mcap", config)
    poses = pass_poses(rec, "reference", config)
    kept = pass_scans(rec, poses, 1, config.em)
    step = np.hypot(*np.diff(poses.poses[:, :2], axis=0).T)
    standing = int(np.sum(step < 1e-6))
    assert standing >= 45  # 5 s of standing at 10 Hz
    moving = len(rec.scans) - 1 - standing
    assert moving <= len(kept) <= moving + 8  # one scan per second of standing, at most
    every = pass_scans(rec, poses, 1, config.em.model_copy(update={"still_interval_s": 0.0}))
    assert len(every) == len(rec.scans)
    twice = pass_scans(rec, poses, 1, config.em.model_copy(update={"still_interval_s": 0.5}))
    assert 4 <= len(twice) - len(kept) <= 6  # 5 s of standing: one more scan in each of them


def test_the_final_wall_step_thins_a_log_over_its_beam_budget_to_every_kth_scan(tiny_site: list[Path]) -> None:
    """Under em.final_max_beams every beam of every kept scan is there; over it, 1 scan in k of each pass for the
    smallest k whose beams fit (each pass keeps ⌈n / k⌉ of its n scans, so k may exceed ⌈total / budget⌉)."""
    from doorbatch.pipeline.objectmap.stage import final_step_beams

    config = DoorbatchConfig()
    recs = [load_recording(p, config) for p in tiny_site]
    poses = [pass_poses(r, "reference", config) for r in recs]
    scans = [pass_scans(r, p, 1, config.em) for r, p in zip(recs, poses, strict=True)]
    total = sum(sc.ranges.shape[0] for one in scans for sc in one)
    expected = len(collect_beams(recs, poses, config.em, (1, 1)))
    every = final_step_beams(recs, poses, config.em)
    assert every is not None and len(every.beams) == expected and every.scan_thinning == 1
    assert every.beams_before == total and every.scans == sum(map(len, scans))

    def kept(k: int) -> int:
        return sum(sc.ranges.shape[0] for one in scans for sc in one[::k])

    for budget in (total // 3 + 1, kept(3), kept(3) - 1, total // 7):
        k = next(k for k in range(1, total) if kept(k) <= budget)
        thinned = final_step_beams(recs, poses, config.em.model_copy(update={"final_max_beams": budget}))
        assert thinned is not None and thinned.scan_thinning == k > 1
        reference = beams_from_scans([one[::k] for one in scans], config.em.max_range_m)
        assert len(thinned.beams) == len(reference) < expected
        np.testing.assert_array_equal(thinned.beams.origin, reference.origin)
    exact = final_step_beams(recs, poses, config.em.model_copy(update={"final_max_beams": total}))
    assert exact is not None and len(exact.beams) == expected and exact.scan_thinning == 1
