"""Dataset-level Parquet tables of ``doorbatch run``, partitioned hive-style by site.

``OUT/metrics/site=<site>/part-0.parquet`` (and ``OUT/trajectories/...``) hold the DESIGN schema of
``metrics`` (``trajectory``); the site is the partition key in the path, not a stored column, so DuckDB
(``read_parquet('OUT/metrics/*/*.parquet', hive_partitioning = true)``), Polars
(``pl.scan_parquet('OUT/metrics', hive_partitioning=True)``), Spark or ``pyarrow.dataset`` read all sites
as one table with a ``site`` column.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pyarrow as pa

from doorbatch.io.parquet import read_table, schema_of, write_table

PARTITION_KEY = "site"
PART_FILE = "part-0.parquet"


def partition_path(root: Path, site: str) -> Path:
    """``root/site=<site>/part-0.parquet``."""
    return root / f"{PARTITION_KEY}={site}" / PART_FILE


def concat_tables(name: str, paths: Sequence[Path]) -> pa.Table:
    """Table ``name`` of each file, checked against its schema, one after the other (empty if none).

    Raises:
        InputDataError: a file is missing or has another schema.
    """
    tables = [read_table(name, p) for p in paths]
    return pa.concat_tables(tables) if tables else schema_of(name).empty_table()


def write_site_partition(name: str, table: pa.Table, root: Path, site: str) -> Path:
    """Write one site's part of table ``name`` under ``root`` (atomically); return its path."""
    path = partition_path(root, site)
    write_table(name, table, path)
    return path


