"""classes.json (DESIGN: EM class parameters, reusable on new logs): a round trip keeps every value, the door
colours per paint included; a bad file is bad input naming the problem."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from doorbatch.errors import InputDataError
from doorbatch.io.object_map import read_classes, write_classes
from doorbatch.pipeline.objectmap.model import ClassParams

MEAN = np.array([[204.0, 203.0, 195.0], [150.0, 104.0, 64.0]])
VAR = np.array([[25.0, 24.0, 26.0], [90.0, 70.0, 40.0]])


@pytest.mark.parametrize("paints", [0, 3])
def test_class_parameters_read_back_as_written(tmp_path: Path, paints: int) -> None:
    rng = np.random.default_rng(paints)
    weight = rng.dirichlet(np.ones(paints)) if paints else np.zeros(0)
    classes = ClassParams(0.87, MEAN, VAR, True, weight, rng.uniform(0, 255, (paints, 3)),
                          rng.uniform(4, 100, (paints, 3)))
    write_classes(tmp_path / "classes.json", classes)
    back = read_classes(tmp_path / "classes.json")
    assert back.door_width_m == classes.door_width_m and back.has_color
    for name in ("color_mean", "color_var", "door_mix_weight", "door_mix_mean", "door_mix_var"):
        np.testing.assert_array_equal(getattr(back, name), getattr(classes, name))
    assert ("door_paints" in json.loads((tmp_path / "classes.json").read_text())) == bool(paints)


@pytest.mark.parametrize(("paint", "message"), [
    ({"weight": 1.0, "color_mean_rgb": [1, 2, 3]}, "missing or malformed"),
    ({"weight": 0.0, "color_mean_rgb": [1, 2, 3], "color_var_rgb": [4, 4, 4]}, "door_paints"),
    ({"weight": 1.0, "color_mean_rgb": [1, 2, 3], "color_var_rgb": [4, -4, 4]}, "door_paints"),
])
def test_a_malformed_paint_is_bad_input(tmp_path: Path, paint: dict[str, object], message: str) -> None:
    write_classes(tmp_path / "classes.json", ClassParams(0.9, MEAN, VAR, True))
    data = json.loads((tmp_path / "classes.json").read_text())
    data["door_paints"] = [paint]
    (tmp_path / "classes.json").write_text(json.dumps(data))
    with pytest.raises(InputDataError, match=message):
        read_classes(tmp_path / "classes.json")
