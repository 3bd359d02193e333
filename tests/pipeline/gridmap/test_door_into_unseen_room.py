"""A door that opens into a room the corridor never sees otherwise, on the bundled simulator's logs (an outside
tester's world, session 33): closed in some passes, open 90° in another. Its open state lies in cells never seen
free, so the grid holds it as static and the static-partner search must find it; the closed leaf's near end is cut
short where it meets the jamb, so a search from that end alone missed the door in 13 of 25 of the tester's runs."""

from __future__ import annotations

import math
from pathlib import Path

import pyarrow.parquet as pq
import pytest
import yaml

from doorbatch.cli import main

HINGE_X, WALL_Y = 5.0, 1.5


def _world(length_m: float, hinge: str, recess_m: float = 0.0, into_room: bool = True,
           twin_gap_m: float | None = None) -> dict[str, object]:
    """A 12 × 3 m corridor, an 8 × 3.5 m room north of it, one door in the wall between (hinged at its west end,
    opening north; or at its east end, the mirror image). With ``recess_m`` the door stands at the back of a recess
    that deep, 0.1 m wider than the leaf on each side (a thick wall, the door flush with its room side). Not
    ``into_room``: the door opens into the corridor instead. With ``twin_gap_m`` a second door, d02, the same, stands
    that far east of the first (no recess)."""
    left = hinge == "left"
    door_y = WALL_Y + recess_m
    door = {"name": "d01", "hinge_m": [HINGE_X if left else HINGE_X + length_m, door_y], "length_m": length_m,
            "closed_yaw_deg": 0 if left else 180, "opening_sign": (1 if left else -1) * (1 if into_room else -1),
            "max_angle_deg": 140.0,
            "material": "door"}
    grey = {"mean_rgb": [200, 200, 195], "std_rgb": [5, 5, 5]}
    a, b = HINGE_X - 0.1, HINGE_X + length_m + 0.1
    north = ([[0.0, WALL_Y], [a, WALL_Y], [a, door_y], [b, door_y], [b, WALL_Y], [12.0, WALL_Y]] if recess_m > 0
             else [[0.0, WALL_Y], [12.0, WALL_Y]])
    return {
        "name": "room_door", "description": "a door into an otherwise unseen room", "wall_height_m": 2.6,
        "floor_rgb": [118, 112, 104], "ceiling_rgb": [236, 236, 230],
        "materials": {"wall": grey, "door": {"mean_rgb": [150, 104, 64], "std_rgb": [10, 8, 6]},
                      "handle": {"mean_rgb": [48, 48, 52], "std_rgb": [3, 3, 3]}},
        "walls": [{"name": "north", "points_m": north},
                  {"name": "south", "points_m": [[0.0, -1.5], [12.0, -1.5]]},
                  {"name": "west", "points_m": [[0.0, -1.5], [0.0, WALL_Y]]},
                  {"name": "east", "points_m": [[12.0, -1.5], [12.0, WALL_Y]]}],
        "rooms": [{"name": "room", "points_m": [[2.0, door_y], [2.0, 5.0], [10.0, 5.0], [10.0, door_y]]}],
        "pillars": [], "niches": [],
        "doors": [door] if twin_gap_m is None else [door, {**door, "name": "d02", "hinge_m": [
            door["hinge_m"][0] + length_m + twin_gap_m, door_y]}],
        "routes": {"main": {"points_m": [[1.0, -0.7], [11.0, -0.7]]}},
    }


def _scenario(angles_deg: tuple[float, ...], names: tuple[str, ...] = ("d01",)) -> dict[str, object]:
    passes = [{"name": f"pass{k + 1}", "route": "main", "reverse": k % 2 == 1, "dwell_s": 1.0, "doors": "closed",
               "door_angles_deg": dict.fromkeys(names, a)} for k, a in enumerate(angles_deg)]
    laser = {"rate_hz": 15.0, "fov_deg": 270.0, "beams": 720, "max_range_m": 20.0, "sigma_m": 0.01,
             "dropout_prob": 0.01}
    return {"name": "room_door", "description": "closed, open, closed", "start_time_s": 1700000000,
            "door_swing_s": 1.0, "robot": {"max_speed_mps": 1.0}, "passes": passes, "people": [],
            "sensors": {"laser": laser, "camera": {"enabled": False}, "detections": {"enabled": False},
                        "colors": {"enabled": False}}}


def _mapped_doors(tmp_path: Path, world: dict[str, object], angles_deg: tuple[float, ...], seed: int
                  ) -> list[dict[str, float]]:
    (tmp_path / "world.yaml").write_text(yaml.safe_dump(world))
    names = tuple(str(d["name"]) for d in world["doors"])  # type: ignore[attr-defined]
    (tmp_path / "scenario.yaml").write_text(yaml.safe_dump(_scenario(angles_deg, names)))
    assert main(["simulate", str(tmp_path / "world.yaml"), "-o", str(tmp_path / "sim" / "run.mcap"), "--scenario",
                 str(tmp_path / "scenario.yaml"), "--seed", str(seed), "--split-passes", "-q"]) == 0
    passes = [str(tmp_path / "sim" / f"run_pass{k + 1}.mcap") for k in range(len(angles_deg))]
    assert main(["map", *passes, "-o", str(tmp_path / "map"), "--stages", "grid", "-q"]) == 0
    return list(pq.read_table(tmp_path / "map" / "doors.parquet").to_pylist())


def _open_range_deg(door: dict[str, float]) -> tuple[float, float]:
    """The door's range as leaf directions in the world (degrees, sorted)."""
    ends = (math.degrees(door["closed_yaw"] + door[k]) for k in ("angle_min", "angle_max"))
    return tuple(sorted((e + 180.0) % 360.0 - 180.0 for e in ends))  # type: ignore[return-value]


@pytest.mark.parametrize(("length_m", "hinge", "angles_deg", "seed"), [
    (0.9, "left", (0.0, 90.0, 0.0), 2),  # the tester's cases that were missed
    (0.8, "left", (0.0, 90.0, 0.0), 1),
    (0.9, "right", (0.0, 0.0, 90.0), 2),
    (1.2, "left", (0.0, 90.0, 0.0), 1),  # a 1.2 m leaf (hospital rooms): λmax was 1.2, its lines measure a cell more
])
def test_a_door_opened_into_an_unseen_room_is_found(tmp_path: Path, length_m: float, hinge: str,
                                                    angles_deg: tuple[float, ...], seed: int) -> None:
    doors = _mapped_doors(tmp_path, _world(length_m, hinge), angles_deg, seed)
    assert len(doors) == 1
    door = doors[0]
    hinge_x = HINGE_X if hinge == "left" else HINGE_X + length_m
    assert math.hypot(door["hinge_x"] - hinge_x, door["hinge_y"] - WALL_Y) <= 0.10
    assert abs(door["length"] - length_m) <= 0.10
    # closed along the wall towards the doorway, open 90° into the room (north) at the far end of the range
    closed = 0.0 if hinge == "left" else math.pi
    assert abs(math.remainder(door["closed_yaw"] - closed, 2 * math.pi)) <= math.radians(10.0)
    ends = sorted(abs(a) for a in (door["angle_min"], door["angle_max"]))
    assert ends[0] <= math.radians(10.0) and abs(ends[1] - math.pi / 2) <= math.radians(10.0)
    open_yaw = door["closed_yaw"] + (door["angle_max"] if abs(door["angle_max"]) > abs(door["angle_min"])
                                     else door["angle_min"])
    assert math.sin(open_yaw) > 0.99  # into the room


@pytest.mark.parametrize(("recess_m", "angles_deg"), [(0.25, (0.0, 45.0, 90.0)), (0.15, (0.0, 45.0, 90.0))])
def test_a_door_at_the_back_of_a_recess_keeps_its_whole_range(tmp_path: Path, recess_m: float,
                                                             angles_deg: tuple[float, ...]) -> None:
    """Closed, 45° and 90° into the room, the 90° state static (the 45° leaf hides it in the last pass). The wall
    behind the hinge is hidden from the corridor, so the recess corner's diagonal passed for it: the door was read
    as closed at 45° and its static state searched on the other side only (range 0-45°, an outside tester's
    world, three seeds)."""
    doors = _mapped_doors(tmp_path, _world(0.9, "left", recess_m), angles_deg, seed=1)
    assert len(doors) == 1
    door = doors[0]
    assert math.hypot(door["hinge_x"] - HINGE_X, door["hinge_y"] - (WALL_Y + recess_m)) <= 0.10
    assert abs(door["length"] - 0.9) <= 0.10
    lo, hi = _open_range_deg(door)
    assert abs(lo - 0.0) <= 10.0 and abs(hi - 90.0) <= 10.0
    # and closed is closed: the 90° leaf's own cells, behind the hinge seen from -90°, are not a wall to close against
    assert abs(math.degrees(math.remainder(door["closed_yaw"], 2 * math.pi))) <= 10.0


@pytest.mark.parametrize(("into_room", "angles_deg", "seed"), [(False, (0.0, 90.0, 0.0), 1),
                                                               (True, (0.0, 45.0, 90.0), 1)])
def test_a_narrow_door_is_found(tmp_path: Path, into_room: bool, angles_deg: tuple[float, ...], seed: int) -> None:
    """A 0.6 m leaf (a closet's, a 625 mm European door's): its lines in one scan lose up to 0.1 m where its ends
    meet static cells, so with the length gate at 0.6 m it was never found (4 of 4 of an outside tester's runs, on
    the bundled simulator and their own)."""
    doors = _mapped_doors(tmp_path, _world(0.6, "left", into_room=into_room), angles_deg, seed)
    assert len(doors) == 1
    door = doors[0]
    assert math.hypot(door["hinge_x"] - HINGE_X, door["hinge_y"] - WALL_Y) <= 0.10
    assert abs(door["length"] - 0.6) <= 0.10
    lo, hi = _open_range_deg(door)
    expected = (0.0, 90.0) if into_room else (-90.0, 0.0)
    assert abs(lo - expected[0]) <= 10.0 and abs(hi - expected[1]) <= 10.0


def test_twin_doors_into_one_room_keep_their_whole_ranges(tmp_path: Path) -> None:
    """Two doors 0.3 m apart into one room, closed, 45° and 90° (an outside tester's world, session 33). The second
    door's 90° leaf stands where, before that pass, only its far part was seen free (through the first doorway): its
    near 0.55 m was integrated as static, its far 0.35 m were dynamic points, too short for a leaf, so its range was
    0-45°. Points in cells never seen before the pass now complete a line of dynamic points as points seen free do."""
    doors = _mapped_doors(tmp_path, _world(0.9, "left", twin_gap_m=0.3), (0.0, 45.0, 90.0), seed=1)
    assert len(doors) == 2
    for hinge_x in (HINGE_X, HINGE_X + 1.2):
        door = min(doors, key=lambda d: abs(d["hinge_x"] - hinge_x))
        assert math.hypot(door["hinge_x"] - hinge_x, door["hinge_y"] - WALL_Y) <= 0.10
        assert abs(door["length"] - 0.9) <= 0.10
        lo, hi = _open_range_deg(door)
        assert abs(lo - 0.0) <= 10.0 and abs(hi - 90.0) <= 10.0
