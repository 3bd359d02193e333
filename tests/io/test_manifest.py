"""manifest.json: fingerprints, stage times, UTC times, JSON round trip, rejection of foreign files."""

from __future__ import annotations

import hashlib
import json
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

import doorbatch
from doorbatch.config import DoorbatchConfig
from doorbatch.errors import InputDataError
from doorbatch.io.manifest import BLOCK_BYTES, Manifest, StageTimer, code_fingerprint, config_hash, file_fingerprint


def test_file_fingerprint_is_sha256_of_content_across_blocks(tmp_path: Path) -> None:
    data = np.random.default_rng(1).bytes(BLOCK_BYTES * 2 + 123)
    path = tmp_path / "log.mcap"
    path.write_bytes(data)
    assert file_fingerprint(path) == {"path": str(path), "size": len(data),
                                      "sha256": hashlib.sha256(data).hexdigest()}


def test_folder_fingerprint_covers_every_file_in_sorted_order(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    (bag / "sub").mkdir(parents=True)
    (bag / "metadata.yaml").write_text("version: 5\n")
    (bag / "bag_0.db3").write_bytes(b"\x01" * 1000)
    (bag / "sub" / "x").write_bytes(b"xyz")
    first = file_fingerprint(bag)
    assert first["size"] == 11 + 1000 + 3
    expected = hashlib.sha256()
    for name, content in [("bag_0.db3", b"\x01" * 1000), ("metadata.yaml", b"version: 5\n"), ("sub/x", b"xyz")]:
        expected.update(f"{name}\0{len(content)}\0".encode() + content)
    assert first["sha256"] == expected.hexdigest()
    (bag / "sub" / "x").rename(bag / "sub" / "y")  # same bytes, another name: another fingerprint
    assert file_fingerprint(bag)["sha256"] != first["sha256"]


def test_fingerprint_of_missing_input_names_it(tmp_path: Path) -> None:
    with pytest.raises(InputDataError) as info:
        file_fingerprint(tmp_path / "gone.bag")
    assert info.value.path == str(tmp_path / "gone.bag")


def test_stage_timer_accumulates_per_stage_also_on_error(monkeypatch: pytest.MonkeyPatch) -> None:
    clock = iter([10.0, 12.5, 20.0, 20.5, 30.0, 31.25])  # a fake perf_counter: start, end of each stage
    monkeypatch.setattr("doorbatch.io.manifest.time.perf_counter", lambda: next(clock))
    timer = StageTimer()
    with timer.stage("grid"):
        pass
    with timer("grid"):
        pass
    with pytest.raises(RuntimeError), timer.stage("em"):
        raise RuntimeError
    assert timer.seconds == {"grid": 3.0, "em": 1.25}  # 2.5 + 0.5, and the stage that raised


def test_config_hash_equals_the_config_models_hash() -> None:
    config = DoorbatchConfig()
    assert config_hash(config.as_dict()) == config.hash()
    assert Manifest.start(config.as_dict()).config_hash == config.hash()


def test_manifest_write_read_round_trip(tmp_path: Path) -> None:
    log = tmp_path / "a.mcap"
    log.write_bytes(b"\x89MCAP0\r\n")
    config = DoorbatchConfig().as_dict()
    manifest = Manifest.start(config, [log], command="map")
    manifest.warn("stamps repaired in a.mcap")
    timer = StageTimer()
    with timer.stage("grid"):
        pass
    manifest.finish(timer)
    manifest.extra["n_doors"] = np.int32(3)
    manifest.write(tmp_path / "out" / "manifest.json")

    data = json.loads((tmp_path / "out" / "manifest.json").read_text())
    assert list(data) == ["manifest_version", "doorbatch_version", "config", "config_hash", "inputs",
                          "started_at", "finished_at", "stage_seconds", "warnings", "extra"]
    assert data["doorbatch_version"] == doorbatch.__version__
    assert data["config"] == config
    assert data["inputs"] == [file_fingerprint(log)]
    assert data["warnings"] == ["stamps repaired in a.mcap"]
    assert data["extra"] == {"command": "map", "n_doors": 3, "code_sha256": code_fingerprint()}
    assert set(data["stage_seconds"]) == {"grid"}
    started = datetime.fromisoformat(data["started_at"])
    finished = datetime.fromisoformat(data["finished_at"])
    assert started.tzinfo == UTC and data["started_at"].endswith("Z")
    assert started <= finished

    back = Manifest.read(tmp_path / "out" / "manifest.json")
    assert back.to_dict() == data


@pytest.mark.parametrize(
    ("text", "message"),
    [("{not json", "cannot read manifest"), ("[1, 2]", "not a JSON object"),
     ('{"config": {}}', "missing"), ('{"config": [], "config_hash": "", "doorbatch_version": "", '
                                    '"started_at": ""}', "wrong kind")],
)
def test_read_rejects_foreign_files(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "manifest.json"
    path.write_text(text)
    with pytest.raises(InputDataError, match=message) as info:
        Manifest.read(path)
    assert info.value.path == str(path)


def test_a_nan_or_infinity_is_written_as_null_which_strict_parsers_read(tmp_path: Path) -> None:
    manifest = Manifest.start({"doorpose": {"door_width_max_m": float("inf")}})
    manifest.extra.update(log_posterior=float("nan"), lost_after_s=[1.5, float("-inf")], size=np.float32("nan"))
    manifest.write(tmp_path / "manifest.json")

    def refuse(name: str) -> None:
        raise ValueError(f"{name} is not JSON")

    data = json.loads((tmp_path / "manifest.json").read_text(), parse_constant=refuse)
    # a config's inf ("no limit") as its text: it reads back as the config, and hashes as it
    assert data["config"] == {"doorpose": {"door_width_max_m": "inf"}}
    assert data["config_hash"] == config_hash(data["config"]) == config_hash(manifest.config)
    assert DoorbatchConfig.model_validate(data["config"]).doorpose.door_width_max_m == float("inf")
    assert (data["extra"]["log_posterior"], data["extra"]["lost_after_s"], data["extra"]["size"]) == (None, [1.5, None],
                                                                                                        None)
    assert Manifest.read(tmp_path / "manifest.json").extra["lost_after_s"] == [1.5, None]


def test_unserializable_extra_fails_before_writing(tmp_path: Path) -> None:
    manifest = Manifest.start({})
    manifest.extra["bad"] = object()
    with pytest.raises(TypeError):
        manifest.write(tmp_path / "manifest.json")
    assert list(tmp_path.iterdir()) == []


def test_the_code_fingerprint_changes_with_any_source_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The hash covers every .py file of the package by path and bytes: a copy of the package with one byte
    changed in one module has another fingerprint; __pycache__ is left out."""
    import shutil

    import doorbatch as pkg
    from doorbatch.io import manifest as mf

    copy = Path(shutil.copytree(Path(pkg.__file__).parent, tmp_path / "doorbatch",
                                ignore=shutil.ignore_patterns("__pycache__")))
    monkeypatch.setattr(mf.doorbatch, "__file__", str(copy / "__init__.py"))
    mf.code_fingerprint.cache_clear()
    same = mf.code_fingerprint()
    (copy / "__pycache__").mkdir(exist_ok=True)
    (copy / "__pycache__" / "x.py").write_text("cached")
    mf.code_fingerprint.cache_clear()
    assert mf.code_fingerprint() == same
    errors = copy / "errors.py"
    errors.write_text(errors.read_text() + "\n")
    mf.code_fingerprint.cache_clear()
    assert mf.code_fingerprint() != same
    mf.code_fingerprint.cache_clear()
