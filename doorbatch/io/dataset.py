"""``DATASET/dataset.yaml``: the sites of a dataset, their mapping and localization logs, optional truth.

Layout (DESIGN.md, Command line), paths relative to the dataset folder::

    sites:
      office_corridor:
        mapping: [logs/map_pass1.mcap, logs/map_pass2.mcap]       # one pass per log, at least one
        localization: [logs/loc_closed.mcap, nightly/*.mcap]      # may be empty; a pattern: the logs it matches
        truth: truth/office_corridor.yaml                         # optional
    config: {}                                                    # optional overrides for this dataset

Only the layout is checked here; whether each log reads is the pipeline's business (a missing or corrupt
log fails its own steps, not the whole dataset).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from doorbatch.config import read_yaml_mapping
from doorbatch.errors import ConfigError, InputDataError
from doorbatch.io.run_log import RUN_LOG, SUMMARY_FILE

DATASET_FILE = "dataset.yaml"
# a folder name and a hive partition value without escaping; no leading dot (".", "..", hidden leftovers)
_SITE_NAME = re.compile(r"^[A-Za-z0-9_-][A-Za-z0-9_.-]*$")
_LOG_SUFFIXES = (".gz", ".mcap", ".bag", ".db3", ".log", ".clf")


@dataclass(frozen=True)
class Site:
    """One site: the logs its map is built from, the logs localized on that map, and its truth file."""

    name: str
    mapping: tuple[Path, ...]
    localization: tuple[Path, ...]
    truth: Path | None = None


@dataclass(frozen=True)
class Dataset:
    """A dataset folder: its sites (in file order) and its ``config:`` overrides."""

    root: Path
    sites: tuple[Site, ...]
    config: dict[str, Any]


def log_name(path: Path) -> str:
    """The name a log's outputs go under: its file name less log suffixes (``loc.log.gz`` → ``loc``)."""
    name = Path(path).name
    while True:
        stem, dot, suffix = name.rpartition(".")
        if not dot or not stem or f".{suffix}" not in _LOG_SUFFIXES:
            return name
        name = stem


SITE_KEYS = ("mapping", "localization", "truth")


def _layout_error(message: str, where: Path) -> ConfigError:
    """dataset.yaml is the batch's configuration, as its ``config:`` block is: a layout that does not fit is a config
    error (exit 2) naming the file."""
    return ConfigError(f"{where}: {message}")


def _closest(unknown: list[str], valid: tuple[str, ...]) -> str:
    """", did you mean 'x'?" for the first unknown key that resembles a valid one, else ""."""
    for key in unknown:
        close = difflib.get_close_matches(str(key), valid, n=1, cutoff=0.6)
        if close:
            return f", did you mean {close[0]!r}?"
    return ""


def _paths(root: Path, site: str, key: str, value: Any, where: Path) -> tuple[Path, ...]:
    if value is None:
        return ()
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise _layout_error(f"sites.{site}.{key} must be a list of paths relative to the dataset", where)
    paths: list[Path] = []
    for v in value:  # a pattern (logs/*.mcap, 2026/**/loc_*.bag) stands for the logs it matches, in name order
        if not _GLOB.search(v):
            paths.append(root / v)
            continue
        if Path(v).is_absolute():
            raise _layout_error(f"sites.{site}.{key}: {v!r}: a pattern must be relative to the dataset", where)
        # as a shell matches: names starting with "." are not (macOS's ._x.mcap, a writer's temporary files); nor
        # are the outputs of a doorbatch run whose OUT lies in the dataset (a folder with its run.log)
        paths += sorted(p for p in root.glob(v) if not any(part.startswith(".") for part in p.relative_to(root).parts)
                        and not _in_run_output(p, root))
    return tuple(dict.fromkeys(paths))  # a log matched twice is one log


_GLOB = re.compile(r"[*?\[]")  # a path with these is a pattern


def _in_run_output(path: Path, root: Path) -> bool:
    """Whether ``path`` lies in the output folder of a ``doorbatch run`` (one that holds its run.log and
    summary.json) below ``root``."""
    return any((folder / RUN_LOG).is_file() and (folder / SUMMARY_FILE).is_file()
               for folder in path.parents if folder != root and root in folder.parents)


def _site(root: Path, name: Any, entry: Any, where: Path) -> Site:
    if not isinstance(name, str) or not _SITE_NAME.match(name):
        raise _layout_error(f"site name {name!r}: use letters, digits, '_', '-', '.' (not first)", where)
    if not isinstance(entry, dict):
        raise _layout_error(f"sites.{name} must be a mapping with mapping/localization/truth", where)
    unknown = sorted(set(entry) - set(SITE_KEYS))
    if unknown:
        raise _layout_error(f"sites.{name}: unknown key(s) {unknown}{_closest(unknown, SITE_KEYS)} "
                            "(mapping, localization, truth)", where)
    mapping = _paths(root, name, "mapping", entry.get("mapping"), where)
    if not mapping:
        raise _layout_error(f"sites.{name}.mapping: at least one mapping log is needed (a pattern that matches "
                            "none gives none)", where)
    localization = _paths(root, name, "localization", entry.get("localization"), where)
    names = [log_name(p) for p in localization]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise _layout_error(f"sites.{name}.localization: two logs share the output name(s) {twice} (OUT/{name}/runs/"
                            "<name>: rename one, or list them under two sites)", where)
    truth = entry.get("truth")
    if truth is not None and not (isinstance(truth, str) and truth):
        raise _layout_error(f"sites.{name}.truth must be a path relative to the dataset", where)
    return Site(name, mapping, localization, root / truth if truth else None)


def read_dataset(root: Path) -> Dataset:
    """Read ``root/dataset.yaml``.

    Raises:
        InputDataError: no dataset.yaml in ``root``.
        ConfigError: bad YAML, or a layout that does not fit (names the key; the closest valid one for an unknown
            key).
    """
    root = Path(root)
    where = root / DATASET_FILE
    if not where.is_file():
        raise InputDataError(f"no {DATASET_FILE} in the dataset folder", path=root)
    data = read_yaml_mapping(where)  # bad YAML: a ConfigError naming the file
    unknown = sorted(set(data) - {"sites", "config"})
    if unknown:
        raise _layout_error(f"unknown top-level key(s) {unknown}{_closest(unknown, ('sites', 'config'))} "
                            "(sites, config)", where)
    sites = data.get("sites")
    if not isinstance(sites, dict) or not sites:
        raise _layout_error("'sites' must map at least one site name to its logs", where)
    config = data.get("config") or {}
    if not isinstance(config, dict):
        raise _layout_error("'config' must be a mapping of config sections", where)
    return Dataset(root, tuple(_site(root, k, v, where) for k, v in sites.items()), config)
