"""Fixtures of the ``doorbatch run`` tests: the tiny dataset (built once) and one uninterrupted run of it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from doorbatch.cli import main
from tests.pipeline.batch.tiny_dataset import make_tiny_dataset


@pytest.fixture(scope="session")
def tiny_master(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The tiny dataset, built once per session (tests copy it before changing it)."""
    return make_tiny_dataset(tmp_path_factory.mktemp("master") / "tiny")


@pytest.fixture
def tiny(tmp_path: Path, tiny_master: Path) -> Path:
    """A copy of the tiny dataset that a test may change (same folder name: reports carry it as title)."""
    return Path(shutil.copytree(tiny_master, tmp_path / "data" / "tiny"))


@pytest.fixture(scope="session")
def reference_out(tmp_path_factory: pytest.TempPathFactory, tiny_master: Path) -> Path:
    """The output of one uninterrupted local run of the tiny dataset (never changed by tests)."""
    out = tmp_path_factory.mktemp("reference") / "out"
    assert main(["run", str(tiny_master), "-o", str(out), "--workers", "1", "-q"]) == 0
    return out
