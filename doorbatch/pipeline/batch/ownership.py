"""``doorbatch run`` replaces only folders it wrote: each step's folder, OUT/metrics and OUT/trajectories are
replaced whole (:func:`~doorbatch.io.staged_dir.staged_dir`), so an existing one that holds anything else (logs,
someone's report) would be deleted with them.

A step folder is doorbatch's when its manifest.json carries a step record
(:func:`~doorbatch.pipeline.batch.freshness.recorded_step`) listing every file in it; a table folder when it holds
only site partitions (``site=<name>/part-0.parquet``). No input of the dataset may lie inside a folder the run writes.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path

from doorbatch.errors import UsageError
from doorbatch.io.dataset import Dataset
from doorbatch.io.dataset_tables import PART_FILE, PARTITION_KEY
from doorbatch.io.staged_dir import is_leftover
from doorbatch.pipeline.batch.freshness import MANIFEST, OUTPUTS, recorded_step
from doorbatch.pipeline.batch.plan import METRICS_DIR, TRAJECTORIES_DIR, Step


def _inputs(dataset: Dataset) -> list[Path]:
    paths = [dataset.root / "dataset.yaml"]
    for site in dataset.sites:
        paths += [*site.mapping, *site.localization, *([site.truth] if site.truth is not None else [])]
    return [p.resolve() for p in paths]


def _files(folder: Path) -> Iterator[Path]:
    """The files under ``folder`` in name order, a killed run's staged leftovers left out."""
    return (p for p in sorted(folder.rglob("*")) if p.is_file() and not is_leftover(p))


def _foreign_step_file(folder: Path) -> Path | None:
    """A file in a step's folder that the step did not write: any file where no manifest records the step, else
    one its record's outputs do not list (a user's notes.md added to OUT/report since)."""
    record = recorded_step(folder)
    if record is None:
        return next(_files(folder), None)
    outputs = record.get(OUTPUTS)
    if not isinstance(outputs, dict):  # a record from before outputs were recorded: its files cannot be told
        return None
    return next((p for p in _files(folder) if p.name != MANIFEST and p.relative_to(folder).as_posix() not in outputs),
                None)


def _foreign_table_entry(folder: Path) -> Path | None:
    """A path in a table folder that is not a site partition's part file (None: all are)."""
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).parts
        if is_leftover(path) or any(is_leftover(Path(p)) for p in rel):
            continue
        partition_dir = len(rel) == 1 and path.is_dir()
        part_file = len(rel) == 2 and rel[1] == PART_FILE and path.is_file()
        if not (rel[0].startswith(f"{PARTITION_KEY}=") and (partition_dir or part_file)):
            return path
    return None


def _inside(path: Path, folders: Iterable[Path]) -> Path | None:
    return next((f for f in folders if path == f or f in path.parents), None)


def check_owned_outputs(out: Path, steps: Sequence[Step], dataset: Dataset) -> None:
    """Refuse, before any work, a run that would replace a folder of OUT it did not write.

    Raises:
        UsageError: names the folder and one file in it that is not doorbatch's, or the input inside it.
    """
    step_dirs = [(out / s.out_dir).resolve() for s in steps]
    table_dirs = [(out / d).resolve() for d in (METRICS_DIR, TRAJECTORIES_DIR)]
    for path in _inputs(dataset):
        if (folder := _inside(path, step_dirs + table_dirs)) is not None:
            raise UsageError(f"-o {out}: the run replaces {folder} whole, and the dataset's {path} lies inside it; "
                             "write the run's outputs elsewhere (-o a folder outside the dataset's logs)")
    for folder in step_dirs:
        if folder.is_dir() and (foreign := _foreign_step_file(folder)) is not None:
            raise UsageError(f"-o {out}: {folder} holds files doorbatch run did not write (e.g. {foreign}), and the "
                             "run would replace it whole; move them, or write the run's outputs elsewhere")
    for folder in table_dirs:
        if folder.is_dir() and (foreign := _foreign_table_entry(folder)) is not None:
            raise UsageError(f"-o {out}: {folder} holds {foreign}, which doorbatch run did not write, and the run "
                             "would replace the folder whole; move it, or write the run's outputs elsewhere")
