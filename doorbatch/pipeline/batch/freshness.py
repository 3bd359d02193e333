"""Incremental runs: a step is up to date when its folder's manifest records the same step key.

The key is the SHA-256 of the step's identity (kind and parameters such as the method), the content hash
of every input file (:func:`~doorbatch.io.manifest.file_fingerprint`, by name and SHA-256: moving the
dataset does not invalidate it), and the hash of the resolved config sections the step depends on (a
change to ``localize.sigma_hit`` redoes localization, not mapping), and the hash of doorbatch's own source
(:func:`~doorbatch.io.manifest.code_fingerprint`: an upgrade redoes every step). Outputs of an upstream step are inputs
of the next by content, so a rerun of mapping that yields the same map leaves localization skipped.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from doorbatch.config import tree_hash
from doorbatch.errors import InputDataError
from doorbatch.io.manifest import Manifest, StageTimer, code_fingerprint, file_fingerprint
from doorbatch.pipeline.batch.plan import StepKind

MANIFEST = "manifest.json"
STEP_RECORD = "step"  # the key of the step record in manifest.extra
OUTPUTS = "outputs"  # in the step record: the files the step wrote into its folder, by relative path and size

# Config sections each kind of step reads (absent ones are left out: evaluation's section lands separately).
_READING = ("seed", "topics", "frames", "io", "laser")
STEP_SECTIONS: dict[StepKind, tuple[str, ...]] = {
    StepKind.MAP: (*_READING, "scanmatch", "mapping", "grid", "doors"),
    StepKind.LOCALIZE: (*_READING, "mapping.max_pose_gap_s", "localize"),  # it bounds odometry gaps
    StepKind.EVALUATE: (*_READING, "doors", "evaluate"),
    StepKind.REPORT: ("evaluate",),
}


def sections_hash(config: Mapping[str, Any], sections: Sequence[str]) -> str:
    """SHA-256 of the named sections of a resolved config tree (canonical JSON); ``section.key`` names one key
    of a section (localization reads one key of ``mapping``: a mapping change that leaves the map as it was
    does not redo it)."""
    picked: dict[str, Any] = {}
    for name in sections:
        section, _, key = name.partition(".")
        if section in config and (not key or key in config[section]):
            picked[name] = config[section][key] if key else config[section]
    return tree_hash(picked)


@dataclass(frozen=True)
class StepKey:
    """What a step's output depends on; :attr:`digest` is the key compared between runs."""

    kind: StepKind
    params: dict[str, Any]
    sections: tuple[str, ...]
    sections_hash: str
    code_sha256: str
    inputs: list[dict[str, Any]] = field(default_factory=list)

    @property
    def digest(self) -> str:
        """SHA-256 over kind, params, the sections' hash, each input's name and content hash, and doorbatch's own
        source (an upgrade redoes every step: a version number does not change with each commit)."""
        return tree_hash({"kind": str(self.kind), "params": self.params, "sections_hash": self.sections_hash,
                          "inputs": [[Path(i["path"]).name, i["sha256"]] for i in self.inputs],
                          "code": self.code_sha256})

    def record(self) -> dict[str, Any]:
        """The step record stored in the manifest."""
        return {"kind": str(self.kind), "key": self.digest, "params": self.params, "sections": list(self.sections),
                "sections_hash": self.sections_hash, "inputs": self.inputs, "code_sha256": self.code_sha256}


def step_key(kind: StepKind, config: Mapping[str, Any], inputs: Sequence[Path],
             params: Mapping[str, Any] | None = None,
             fingerprint: Callable[[Path], dict[str, Any]] = file_fingerprint) -> StepKey:
    """Fingerprint a step's inputs (with ``fingerprint``: a cache's, or hashing every byte) and config
    sections.

    Raises:
        InputDataError: an input is missing or unreadable (names it).
    """
    sections = STEP_SECTIONS[kind]
    return StepKey(kind, json.loads(json.dumps(dict(params or {}), default=str)), sections,
                   sections_hash(config, sections), code_fingerprint(), [fingerprint(p) for p in inputs])


def recorded_step(out_dir: Path) -> dict[str, Any] | None:
    """The step record in ``out_dir``/manifest.json, or ``None`` (no folder, no manifest, not a step's)."""
    path = out_dir / MANIFEST
    if not path.is_file():
        return None
    try:
        record = Manifest.read(path).extra.get(STEP_RECORD)
    except InputDataError:
        return None
    return record if isinstance(record, dict) and isinstance(record.get("key"), str) else None


def recorded_key(out_dir: Path) -> str | None:
    """The step key in ``out_dir``/manifest.json, or ``None``."""
    record = recorded_step(out_dir)
    return None if record is None else str(record["key"])


def stamp_manifest(out_dir: Path, key: StepKey, config: Mapping[str, Any], started_at: str,
                   warnings: Sequence[str] = (), timer: StageTimer | None = None) -> None:
    """Add the step record to the manifest a stage wrote in ``out_dir``, or write one if it wrote none (with the
    stage times of ``timer``, as DESIGN asks of every manifest)."""
    path = out_dir / MANIFEST
    if path.is_file():
        manifest = Manifest.read(path)
    else:
        manifest = Manifest.start(config)
        manifest.started_at = started_at
        manifest.inputs = list(key.inputs)
        for w in warnings:
            manifest.warn(w)
        manifest.finish(timer)
    manifest.extra[STEP_RECORD] = {**key.record(), OUTPUTS: _files_of(out_dir)}
    manifest.write(path)


def _files_of(folder: Path) -> dict[str, int]:
    """{relative path: size} of the files in ``folder``, its manifest left out."""
    return {p.relative_to(folder).as_posix(): p.stat().st_size for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != MANIFEST}


def is_up_to_date(out_dir: Path, digest: str) -> bool:
    """Whether ``out_dir`` holds the outputs of the step whose key is ``digest``: its manifest records that key, and
    every file the step wrote there is still there at its size (a deleted trajectory.parquet or report.html is
    made again, not taken as done; a record from before outputs were recorded is trusted)."""
    record = recorded_step(out_dir)
    if record is None or record["key"] != digest:
        return False
    outputs = record.get(OUTPUTS)
    if not isinstance(outputs, dict):
        return True
    for name, size in outputs.items():
        path = out_dir / name
        if not path.is_file() or path.stat().st_size != size:
            return False
    return True
