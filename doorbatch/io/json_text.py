"""JSON text that strict parsers read: NaN and ±inf, which Python's json writes as bare ``NaN`` / ``Infinity``
(not JSON: JavaScript's JSON.parse, jq and Go refuse them), are written as null."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np


def strict_json(data: Any, indent: int | None = 2) -> str:
    """``data`` as JSON text (no trailing newline), every non-finite float as null; NumPy values as their Python
    ones, paths as text, anything else JSON cannot hold as its ``str``."""
    return json.dumps(_finite(data), indent=indent, allow_nan=False)


def _finite(value: Any) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        value = value.tolist()
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    if value is None or isinstance(value, bool | int | str):
        return value
    return str(value)  # a path, an enum: their text (as json.dumps(default=str) wrote them)
