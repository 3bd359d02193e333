"""Files of the em stage in a map directory: walls.parquet (DESIGN schema) and classes.json (the learned
class parameters of paper 001, reusable on new logs with ``doorbatch map --classes FILE``)."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_write_text
from doorbatch.io.parquet import read_table, write_table
from doorbatch.pipeline.objectmap.model import ClassParams, Wall

CLASSES_FORMAT = "doorbatch-em-classes/1"


def walls_columns(walls: Sequence[Wall]) -> dict[str, object]:
    """walls.parquet columns: one row per segment; (x0, y0) → (x1, y1) along the line n·p = offset."""
    rows = [(j, k, *w.endpoints()[k].ravel(), w.normal[0], w.normal[1], w.offset)
            for j, w in enumerate(walls) for k in range(w.segments.shape[0])]
    names = ["wall_id", "segment_id", "x0", "y0", "x1", "y1", "normal_x", "normal_y", "offset"]
    cols: dict[str, object] = {n: [r[i] for r in rows] for i, n in enumerate(names)}
    cols["wall_id"] = np.array(cols["wall_id"], dtype=np.int32)
    cols["segment_id"] = np.array(cols["segment_id"], dtype=np.int32)
    for n in names[2:]:
        cols[n] = np.array(cols[n], dtype=np.float64)
    return cols


def write_walls(path: Path, walls: Sequence[Wall]) -> None:
    """Write walls.parquet atomically."""
    write_table("walls", walls_columns(walls), path)


def read_walls(path: Path) -> list[Wall]:
    """walls.parquet back into walls (segments re-expressed along each line).

    Raises:
        InputDataError: missing file or wrong schema.
    """
    t = read_table("walls", path).to_pydict()
    walls = []
    for j in sorted(set(t["wall_id"])):
        rows = [i for i, w in enumerate(t["wall_id"]) if w == j]
        normal = np.array([t["normal_x"][rows[0]], t["normal_y"][rows[0]]])
        tangent = np.array([-normal[1], normal[0]])
        segs = np.array([[np.array([t["x0"][i], t["y0"][i]]) @ tangent, np.array([t["x1"][i], t["y1"][i]]) @ tangent]
                         for i in rows])
        walls.append(Wall(normal, float(t["offset"][rows[0]]), segs))
    return walls


def classes_dict(classes: ClassParams) -> dict[str, Any]:
    """classes.json content."""
    def one(c: int) -> dict[str, Any]:
        return {"color_mean_rgb": classes.color_mean[c].tolist(), "color_var_rgb": classes.color_var[c].tolist()}
    out: dict[str, Any] = {"format": CLASSES_FORMAT, "door_width_m": classes.door_width_m,
                           "has_color": classes.has_color, "classes": {"wall": one(0), "door": one(1)}}
    if classes.door_mix_weight.size:  # the door colours per paint (em.door_color_components > 1)
        out["door_paints"] = [{"weight": float(w), "color_mean_rgb": m.tolist(), "color_var_rgb": v.tolist()}
                              for w, m, v in zip(classes.door_mix_weight, classes.door_mix_mean,
                                                 classes.door_mix_var, strict=True)]
    return out


def write_classes(path: Path, classes: ClassParams) -> None:
    """Write classes.json atomically."""
    atomic_write_text(path, json.dumps(classes_dict(classes), indent=2) + "\n")


def read_classes(path: Path) -> ClassParams:
    """Read classes.json.

    Raises:
        InputDataError: unreadable, not JSON, another format, or a missing or malformed field.
    """
    try:
        data = json.loads(Path(path).read_text())
    except OSError as err:
        raise InputDataError(f"cannot read class parameters: {err.strerror or err}", path=path) from err
    except json.JSONDecodeError as err:
        raise InputDataError(f"class parameters are not JSON: {err}", path=path) from err
    if not isinstance(data, dict) or data.get("format") != CLASSES_FORMAT:
        raise InputDataError(f"not a doorbatch classes file (format {CLASSES_FORMAT!r} expected)", path=path)
    try:
        mean = np.array([data["classes"][c]["color_mean_rgb"] for c in ("wall", "door")], dtype=np.float64)
        var = np.array([data["classes"][c]["color_var_rgb"] for c in ("wall", "door")], dtype=np.float64)
        width = float(data["door_width_m"])
        has_color = bool(data["has_color"])
        paints = data.get("door_paints", [])  # optional: absent in files of a one-Gaussian door class
        mix_weight = np.array([float(p["weight"]) for p in paints], dtype=np.float64)
        mix_mean = np.array([p["color_mean_rgb"] for p in paints], dtype=np.float64).reshape(-1, 3)
        mix_var = np.array([p["color_var_rgb"] for p in paints], dtype=np.float64).reshape(-1, 3)
    except (KeyError, TypeError, ValueError) as err:
        raise InputDataError(f"classes file: missing or malformed field: {err}", path=path) from err
    if mean.shape != (2, 3) or var.shape != (2, 3) or not np.all(var > 0) or not width > 0:
        raise InputDataError("classes file: colours must be 3 values per class, variances and width > 0", path=path)
    if not (mix_mean.shape[0] == mix_var.shape[0] == mix_weight.size and np.all(mix_var > 0)
            and np.all(mix_weight > 0)):
        raise InputDataError("classes file: door_paints need a weight > 0, 3 colour values and 3 variances > 0 "
                             "each", path=path)
    return ClassParams(width, mean, var, has_color, mix_weight, mix_mean, mix_var)
