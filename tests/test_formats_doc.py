"""docs/formats.md states the Parquet contracts users read: every column of every table, with its type, in the
order the writers enforce, and nothing else."""

from __future__ import annotations

import pyarrow as pa

from doorbatch.io.parquet import TABLES
from tests.conftest import REPO

_TYPES = {pa.float64(): "float64", pa.int32(): "int32", pa.int64(): "int64", pa.string(): "string",
          pa.bool_(): "bool"}


def test_the_formats_page_lists_every_column_of_every_table_with_its_type() -> None:
    rows = [line.split("|")[1:4] for line in (REPO / "docs" / "formats.md").read_text().splitlines()
            if line.startswith("| ") and line.count("|") == 5]
    documented = [(t.strip(), c.strip(), k.strip()) for t, c, k in rows if t.strip() in TABLES]
    expected = [(name, field.name, _TYPES[field.type]) for name, schema in TABLES.items() for field in schema]
    assert documented == expected
