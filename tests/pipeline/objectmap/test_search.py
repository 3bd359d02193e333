"""Small pieces of the em stage's structure search."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from doorbatch.pipeline.objectmap.search import index_union


@given(st.integers(1, 300), st.lists(st.lists(st.integers(0, 299), max_size=50), max_size=4))
def test_index_union_is_union1d(n: int, parts: list[list[int]]) -> None:
    parts = [[i % n for i in p] for p in parts]
    expected = np.unique(np.concatenate([np.asarray(p, dtype=np.int64) for p in parts])) if parts else np.zeros(0)
    got = index_union(n, *parts)
    assert got.dtype == np.int64 and got.tolist() == expected.astype(np.int64).tolist()
