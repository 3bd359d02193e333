"""The bundled sample dataset: its files exist, read cleanly, and regenerate byte for byte."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from doorbatch.io.inspect import inspect_log
from doorbatch.io.sim_truth import read_truth
from doorbatch.sim.simulate import run_simulation
from tests.conftest import REPO

SAMPLE = REPO / "datasets" / "sample"


def _dataset() -> dict[str, object]:
    data = yaml.safe_load((SAMPLE / "dataset.yaml").read_text())
    assert isinstance(data, dict)
    return data


def test_every_listed_log_exists_and_inspects_without_errors() -> None:
    site = _dataset()["sites"]["office_corridor"]  # type: ignore[index]
    assert len(site["mapping"]) == 3 and len(site["localization"]) == 3
    for rel in site["mapping"] + site["localization"]:
        report = inspect_log(SAMPLE / rel)
        assert report.errors == [], (rel, report.errors)
        roles = {t.role for t in report.topics}
        assert {"scan", "odometry", "reference", "transforms"} <= roles
    truth = read_truth(SAMPLE / site["truth"])
    assert len(truth.passes) == 3


def test_sample_is_small() -> None:
    total = sum(p.stat().st_size for p in SAMPLE.rglob("*") if p.is_file())
    assert total < 15 * 2**20


def test_a_sample_log_regenerates_byte_for_byte(tmp_path: Path) -> None:
    script = (SAMPLE / "regenerate.sh").read_text()
    assert '--seed "$seed"' in script and "seed=11" in script
    out = tmp_path / "loc_closed.mcap"
    run_simulation(SAMPLE / "worlds" / "office_corridor.yaml", out, SAMPLE / "scenarios" / "loc_closed.yaml", seed=11)
    committed = SAMPLE / "logs" / "loc_closed.mcap"
    if out.read_bytes() != committed.read_bytes():
        pytest.fail("datasets/sample/logs/loc_closed.mcap differs from a fresh simulation: run regenerate.sh")
