"""Content digests of a ``doorbatch run`` output folder, for comparing two runs."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

# Fields that differ between two identical runs: wall times, and the absolute paths of inputs and outputs.
TIMING_FIELDS = ("started_at", "finished_at", "stage_seconds")
RUN_RECORDS = ("run.log", "summary.json", ".doorbatch-fingerprints.json")  # run records and caches, not outputs


def _manifest_digest(path: Path, roots: dict[str, str]) -> str:
    text = path.read_text()
    for root, placeholder in roots.items():
        text = text.replace(root, placeholder)
    data = json.loads(text)
    for name in TIMING_FIELDS:
        data.pop(name, None)
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


def output_digests(out: Path, dataset: Path) -> dict[str, str]:
    """Relative path → SHA-256 of every output file; manifests without timing fields and with the output
    and dataset folders replaced by placeholders."""
    roots = {str(out.resolve()): "<OUT>", str(dataset.resolve()): "<DATASET>"}
    digests = {}
    for path in sorted(p for p in out.rglob("*") if p.is_file()):
        rel = path.relative_to(out).as_posix()
        if rel in RUN_RECORDS:
            continue
        digests[rel] = (_manifest_digest(path, roots) if path.name == "manifest.json"
                        else hashlib.sha256(path.read_bytes()).hexdigest())
    return digests
