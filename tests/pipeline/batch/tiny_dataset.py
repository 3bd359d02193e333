"""A tiny dataset for ``doorbatch run`` tests: short windows of the bundled sample's logs (real MCAPs with
ground truth beside them), one site, few particles."""

from __future__ import annotations

import shutil
from pathlib import Path

import yaml

from doorbatch.io.split import copy_window
from tests.conftest import REPO

SAMPLE = REPO / "datasets" / "sample"
T0_NS = 1_700_000_000_000_000_000
MAP_WINDOW_S = 14.0
LOC_WINDOW_S = 7.0
LOCALIZATION = ("loc_closed", "loc_open")


def cut_log(name: str, dest: Path, seconds: float) -> Path:
    """The first ``seconds`` of a sample log into ``dest``, with its truth files beside it."""
    dest.mkdir(parents=True, exist_ok=True)
    out = dest / f"{name}.mcap"
    copy_window(SAMPLE / "logs" / f"{name}.mcap", out, T0_NS, T0_NS + int(seconds * 1e9))
    for suffix in (".truth.tum", ".truth.yaml"):
        if (SAMPLE / "logs" / f"{name}{suffix}").exists():
            shutil.copy(SAMPLE / "logs" / f"{name}{suffix}", dest / f"{name}{suffix}")
    return out


def make_tiny_dataset(root: Path) -> Path:
    """``root``/dataset.yaml with one site: one mapping pass, two localization logs, the mapping truth."""
    logs = root / "logs"
    cut_log("map_pass1", logs, MAP_WINDOW_S)
    for name in LOCALIZATION:
        cut_log(name, logs, LOC_WINDOW_S)
    shutil.copy(SAMPLE / "logs" / "map.truth.yaml", logs / "map.truth.yaml")
    dataset = {
        "sites": {"corridor": {"mapping": ["logs/map_pass1.mcap"],
                               "localization": [f"logs/{n}.mcap" for n in LOCALIZATION],
                               "truth": "logs/map.truth.yaml"}},
        "config": {"localize": {"min_particles": 100, "max_particles": 300, "annotate_particles": 20}},
    }
    (root / "dataset.yaml").write_text(yaml.safe_dump(dataset, sort_keys=False))
    return root
