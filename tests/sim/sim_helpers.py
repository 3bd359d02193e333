"""Helpers for simulator tests: short scenarios built from plain dicts, and the shipped worlds."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from doorbatch.config import deep_merge
from doorbatch.sim.scenario import Scenario, configs_dir, parse_scenario
from doorbatch.sim.world import World, load_world

WORLDS = configs_dir() / "worlds"
OFFICE = WORLDS / "office_corridor.yaml"


def office() -> World:
    """The shipped office corridor world."""
    return load_world(OFFICE)


def short_scenario(**overrides: Any) -> Scenario:
    """A ~6 s single-pass scenario in the office corridor (x from 2 to 6 m) with every sensor on; keys given
    here are merged over it (nested mappings merge, lists and values replace)."""
    base: dict[str, Any] = {
        "name": "short",
        "passes": [{"name": "p1", "waypoints_m": [[2.0, 0.0], [6.0, 0.0]], "dwell_s": 0.5, "doors": "closed",
                    "door_angles_deg": {"d01": 60.0}}],
        "sensors": {"camera": {"rate_hz": 2.0, "width_px": 160, "height_px": 120}},
    }
    return parse_scenario(deep_merge(base, overrides), "test scenario")


def write_scenario(path: Path, scenario: Scenario) -> Path:
    """Write a scenario as YAML (for run_simulation, which reads files)."""
    import yaml

    path.write_text(yaml.safe_dump(scenario.model_dump(mode="json"), sort_keys=False))
    return path
