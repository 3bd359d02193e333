"""Experiment files (``configs/experiments/*.yaml``): read and validate into an ExperimentSpec."""

from __future__ import annotations

from pathlib import Path

import yaml
from pydantic import ValidationError

from doorbatch.errors import ConfigError
from doorbatch.pipeline.evaluate.experiment import ExperimentSpec


def experiment_kind(path: Path) -> str:
    """``doorpose`` for a door pose experiment (paper 003; it names its ``experiment:`` kind), else
    ``localization`` (a sweep of localization runs). Unreadable files are ``localization`` and fail there."""
    try:
        doc = yaml.safe_load(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return "localization"
    return "doorpose" if isinstance(doc, dict) and "experiment" in doc else "localization"


def read_experiment(path: Path) -> ExperimentSpec:
    """The experiment in ``path``, relative paths resolved against its folder.

    Raises:
        ConfigError: unreadable, not YAML, or not a valid experiment (names the file and the key).
    """
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as err:
        raise ConfigError(f"{path}: cannot read experiment file: {err}") from err
    try:
        spec = ExperimentSpec.model_validate(doc)
    except ValidationError as err:
        first = err.errors()[0]
        where = ".".join(str(p) for p in first["loc"])
        raise ConfigError(f"{path}: experiment key {where!r}: {first['msg']}") from err
    return spec.resolved(path.parent)
