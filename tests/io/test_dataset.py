"""dataset.yaml: the sample's, and clear errors for layouts that do not fit."""

from __future__ import annotations

from pathlib import Path

import pytest

from doorbatch.errors import ConfigError, ExitCode, InputDataError
from doorbatch.io.dataset import log_name, read_dataset
from tests.conftest import REPO


def test_the_sample_dataset_reads_with_paths_under_its_folder() -> None:
    root = REPO / "datasets" / "sample"
    dataset = read_dataset(root)
    (site,) = dataset.sites
    assert site.name == "office_corridor"
    assert [p.name for p in site.mapping] == ["map_pass1.mcap", "map_pass2.mcap", "map_pass3.mcap"]
    assert [log_name(p) for p in site.localization] == ["loc_closed", "loc_open", "loc_partial"]
    assert all(p.is_file() for p in (*site.mapping, *site.localization))
    assert site.truth == root / "logs" / "map.truth.yaml"
    assert isinstance(dataset.config, dict)


@pytest.mark.parametrize(("name", "expected"), [
    ("a.mcap", "a"), ("intel.log.gz", "intel"), ("x.clf", "x"), ("run.bag", "run"), ("bag_folder", "bag_folder"),
    ("v1.2.mcap", "v1.2"),
])
def test_log_name_drops_log_suffixes_only(name: str, expected: str) -> None:
    assert log_name(Path("/d") / name) == expected


@pytest.mark.parametrize(("text", "message"), [
    ("sites: {}\n", "at least one site"),
    ("sites: {s: {mapping: []}}\n", "at least one mapping log"),
    ("sites: {s: {mapping: [a.mcap], localisation: [b.mcap]}}\n", "localisation.*did you mean 'localization'"),
    ("sites: {'a/b': {mapping: [a.mcap]}}\n", "site name"),
    ("sites: {'..': {mapping: [a.mcap]}}\n", "site name"),
    ("sites: {.hidden: {mapping: [a.mcap]}}\n", "site name"),
    ("sites: {s: {mapping: [a.mcap], localization: [x/l.mcap, y/l.mcap]}}\n", "share the output name"),
    ("sites: {s: {mapping: [a.mcap]}}\nconfig: [1]\n", "'config' must be a mapping"),
    ("sites: {s: {mapping: [a.mcap]}}\nextra: 1\n", "unknown top-level"),
    ("sites: [\n", "not valid YAML"),
])
def test_bad_layouts_are_config_errors_naming_the_file_and_problem(tmp_path: Path, text: str, message: str) -> None:
    """dataset.yaml configures the batch, as its config: block does (a contracts audit found a bad key there exit 3
    and one in config: exit 2): a config error, exit 2, naming the file."""
    (tmp_path / "dataset.yaml").write_text(text)
    with pytest.raises(ConfigError, match=message) as err:
        read_dataset(tmp_path)
    assert err.value.exit_code == ExitCode.USAGE and "dataset.yaml" in str(err.value)


def test_a_folder_without_dataset_yaml_is_named(tmp_path: Path) -> None:
    with pytest.raises(InputDataError, match=r"no dataset\.yaml") as err:
        read_dataset(tmp_path)
    assert str(tmp_path) in str(err.value)


def test_a_pattern_stands_for_the_logs_it_matches_so_new_logs_are_picked_up(tmp_path: Path) -> None:
    """A nightly folder that grows: `nightly/**/loc_*.mcap` lists every log under it in name order (a log matched
    twice once), and tomorrow's new log without editing dataset.yaml; a mapping pattern that matches nothing is the
    layout error of no mapping log."""
    for rel in ("maps/p1.mcap", "maps/p2.mcap", "nightly/2026/11/29/loc_a.mcap", "nightly/2026/11/30/loc_b.mcap",
                "nightly/README.txt"):
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_bytes(b"")
    (tmp_path / "dataset.yaml").write_text(
        "sites:\n  s: {mapping: ['maps/p*.mcap'], localization: ['nightly/**/loc_*.mcap', 'nightly/2026/11/29/*']}\n")
    site = read_dataset(tmp_path).sites[0]
    assert [p.relative_to(tmp_path).as_posix() for p in site.mapping] == ["maps/p1.mcap", "maps/p2.mcap"]
    assert [p.name for p in site.localization] == ["loc_a.mcap", "loc_b.mcap"]
    (tmp_path / "nightly/2026/12/01").mkdir(parents=True)
    (tmp_path / "nightly/2026/12/01/loc_c.mcap").write_bytes(b"")
    assert [p.name for p in read_dataset(tmp_path).sites[0].localization] == ["loc_a.mcap", "loc_b.mcap", "loc_c.mcap"]
    (tmp_path / "dataset.yaml").write_text("sites:\n  s: {mapping: ['maps/q*.mcap']}\n")
    with pytest.raises(ConfigError, match="at least one mapping log"):
        read_dataset(tmp_path)


def test_a_pattern_skips_hidden_files_and_must_be_relative(tmp_path: Path) -> None:
    """As a shell: `logs/*.mcap` leaves out macOS's `._a.mcap` and a writer's `.a.mcap.<hex>.tmp.mcap`; an
    absolute pattern is a layout error, not a crash."""
    (tmp_path / "logs").mkdir()
    for name in ("a.mcap", "._a.mcap", ".a.mcap.0123456789abcdef.tmp.mcap"):
        (tmp_path / "logs" / name).write_bytes(b"")
    (tmp_path / "dataset.yaml").write_text("sites:\n  s: {mapping: ['logs/*.mcap']}\n")
    assert [p.name for p in read_dataset(tmp_path).sites[0].mapping] == ["a.mcap"]
    (tmp_path / "dataset.yaml").write_text(f"sites:\n  s: {{mapping: ['{tmp_path}/logs/*.mcap']}}\n")
    with pytest.raises(ConfigError, match="must be relative"):
        read_dataset(tmp_path)
