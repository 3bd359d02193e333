"""``manifest.json``: what produced an output folder, from what, and how long each stage took.

Written into every output folder (DESIGN.md, Outputs). JSON object with the keys::

    manifest_version   1
    doorbatch_version  doorbatch.__version__
    config             the resolved config tree
    config_hash        SHA-256 of the config in canonical JSON (sorted keys, no spaces)
    inputs             [{"path", "size" (bytes), "sha256"}] per input file or folder
    started_at         ISO 8601 UTC, e.g. "2024-05-01T12:00:00.000Z"
    finished_at        ISO 8601 UTC, or null while running
    stage_seconds      stage name → wall seconds
    warnings           list of strings
    extra              free-form JSON object; ``code_sha256``: the hash of doorbatch's source (code_fingerprint)

A folder input (a ROS 2 bag folder) is fingerprinted over every file inside, in sorted relative-path
order: its size is their total, its hash covers, per file, ``<relative posix path> NUL <size> NUL`` and
then the file's bytes.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import time
from collections.abc import Iterable, Iterator, Mapping
from contextlib import AbstractContextManager, contextmanager
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Self

import doorbatch
from doorbatch.config import tree_hash
from doorbatch.errors import InputDataError
from doorbatch.io.atomic import atomic_write_text
from doorbatch.io.json_text import nonfinite_as_text, strict_json

log = logging.getLogger(__name__)

MANIFEST_VERSION = 1
BLOCK_BYTES = 1 << 20

# The JSON kind each manifest field must have when read back.
_FIELD_KINDS: dict[str, type | tuple[type, ...]] = {
    "manifest_version": int, "doorbatch_version": str, "config": dict, "config_hash": str,
    "inputs": list, "started_at": str, "finished_at": (str, type(None)), "stage_seconds": dict,
    "warnings": list, "extra": dict,
}


def utc_now_iso() -> str:
    """The current time, ISO 8601 in UTC with milliseconds and a ``Z`` suffix."""
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


config_hash = tree_hash  # the one canonical hash of a config tree (DoorbatchConfig.hash uses it too)


@functools.cache
def code_fingerprint() -> str:
    """SHA-256 of doorbatch's own source: every ``.py`` file of the package, by relative path and bytes. Results of
    other code have another one (``doorbatch_version`` stays the same across commits); ``doorbatch run`` keys its
    steps on it, so that an upgrade redoes them, and every manifest records it (``extra.code_sha256``)."""
    root = Path(doorbatch.__file__).parent
    digest = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*.py") if "__pycache__" not in p.parts):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()


def _hash_into(digest: Any, path: Path) -> None:
    """Feed the bytes of ``path`` to ``digest`` in 1 MiB blocks."""
    with path.open("rb") as f:
        while block := f.read(BLOCK_BYTES):
            digest.update(block)


def folder_files(folder: Path) -> list[tuple[str, Path]]:
    """(relative posix path, path) of every file under ``folder``, sorted by the relative path."""
    files = [(p.relative_to(folder).as_posix(), p) for p in folder.rglob("*") if p.is_file()]
    return sorted(files)


def file_fingerprint(path: Path) -> dict[str, Any]:
    """``{"path", "size", "sha256"}`` of a file, or of a folder's files (see the module docstring). The path is
    absolute, so that ``evaluate`` finds a run's log and map from any working directory.

    Raises:
        InputDataError: The path does not exist or a file cannot be read (names it).
    """
    path = Path(path)
    digest = hashlib.sha256()
    try:
        if path.is_dir():
            size = 0
            for relative, file in folder_files(path):
                file_size = file.stat().st_size
                digest.update(f"{relative}\0{file_size}\0".encode())
                _hash_into(digest, file)
                size += file_size
        else:
            size = path.stat().st_size
            _hash_into(digest, path)
    except OSError as err:
        raise InputDataError(f"cannot read input: {err.strerror or err}", path=path) from err
    return {"path": str(path.absolute()), "size": size, "sha256": digest.hexdigest()}


class StageTimer:
    """Wall time per stage: ``with timer.stage("grid"): ...`` adds the elapsed seconds to ``"grid"``."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        """Time the ``with`` body (also when it raises) and add it to stage ``name``."""
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - start

    def __call__(self, name: str) -> AbstractContextManager[None]:
        """Shorthand for :meth:`stage`: ``with timer("grid"): ...``."""
        return self.stage(name)


def _json_default(value: Any) -> Any:
    """JSON for paths."""
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


@dataclass
class Manifest:
    """The content of ``manifest.json`` (see the module docstring); build with :meth:`start`."""

    config: dict[str, Any]
    config_hash: str
    doorbatch_version: str = doorbatch.__version__
    inputs: list[dict[str, Any]] = field(default_factory=list)
    started_at: str = field(default_factory=utc_now_iso)
    finished_at: str | None = None
    stage_seconds: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    manifest_version: int = MANIFEST_VERSION

    @classmethod
    def start(cls, config: Mapping[str, Any], inputs: Iterable[Path] = (), **extra: Any) -> Self:
        """A manifest started now, with the config's hash and each input's fingerprint.

        Raises:
            InputDataError: An input cannot be read.
        """
        config_dict = dict(config)
        return cls(config=config_dict, config_hash=config_hash(config_dict),
                   inputs=[file_fingerprint(p) for p in inputs], extra={"code_sha256": code_fingerprint(), **extra})

    def add_input(self, path: Path) -> None:
        """Fingerprint one more input."""
        self.inputs.append(file_fingerprint(path))

    def warn(self, message: str) -> None:
        """Record a warning, and log it (the one place a command's warnings reach the terminal)."""
        log.warning("%s", message)
        self.warnings.append(message)

    def finish(self, timer: StageTimer | None = None) -> None:
        """Stamp the end time and take the stage times of ``timer``."""
        if timer is not None:
            self.stage_seconds.update(timer.seconds)
        self.finished_at = utc_now_iso()

    def to_dict(self) -> dict[str, Any]:
        """The manifest as plain data, in the order of the module docstring."""
        data = asdict(self)
        order = ["manifest_version", "doorbatch_version", "config", "config_hash", "inputs", "started_at",
                 "finished_at", "stage_seconds", "warnings", "extra"]
        return {key: data[key] for key in order}

    def to_json(self) -> str:
        """The manifest as indented JSON text ending in a newline, strict JSON (a NaN or infinity as null, which
        jq and JSON.parse read; :func:`~doorbatch.io.json_text.strict_json`; in ``config`` as the text "inf", which
        reads back as the config and hashes as it).

        Raises:
            TypeError: ``extra`` or ``config`` holds something JSON cannot represent.
        """
        data = self.to_dict()
        data["config"] = nonfinite_as_text(data["config"])  # "inf" reads back as the config's float; null would not
        return strict_json(data, default=_json_default) + "\n"

    def write(self, path: Path) -> None:
        """Write ``manifest.json`` atomically."""
        atomic_write_text(path, self.to_json())

    @classmethod
    def read(cls, path: Path) -> Self:
        """Read a manifest written by :meth:`write`.

        Raises:
            InputDataError: Unreadable file, not JSON, or fields missing or of the wrong kind (names it).
        """
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise InputDataError(f"cannot read manifest: {err}", path=path) from err
        if not isinstance(data, dict):
            raise InputDataError("manifest is not a JSON object", path=path)
        missing = [k for k in ("config", "config_hash", "doorbatch_version", "started_at") if k not in data]
        unknown = sorted(set(data) - set(_FIELD_KINDS))
        if missing or unknown:
            raise InputDataError(f"not a doorbatch manifest: missing {missing}, unknown {unknown}", path=path)
        wrong = [k for k, v in data.items() if not isinstance(v, _FIELD_KINDS[k])]
        if wrong:
            raise InputDataError(f"not a doorbatch manifest: fields of the wrong kind: {wrong}", path=path)
        return cls(**data)
