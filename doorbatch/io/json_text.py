"""JSON text that strict parsers read: NaN and ±inf, which Python's json writes as bare ``NaN`` / ``Infinity``
(not JSON: JavaScript's JSON.parse, jq and Go refuse them), are written as null."""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from typing import Any

import numpy as np


def strict_json(data: Any, indent: int | None = 2, default: Callable[[Any], Any] = str) -> str:
    """``data`` as JSON text (no trailing newline), every non-finite float as null; NumPy values as their Python
    ones, anything else JSON cannot hold as ``default`` makes it (its ``str``: a path, an enum as its text).

    Raises:
        Whatever ``default`` raises (a TypeError for what it cannot represent).
    """
    return json.dumps(_finite(data, default), indent=indent, allow_nan=False)


def _finite(value: Any, default: Callable[[Any], Any]) -> Any:
    if isinstance(value, np.ndarray | np.generic):
        value = value.tolist()
    if isinstance(value, dict | list | tuple):
        return _walk(value, lambda v: _finite(v, default))
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if value is None or isinstance(value, bool | int | str):
        return value
    return _finite(default(value), default)


def nonfinite_as_text(value: Any) -> Any:
    """``value`` (plain data) with every non-finite float as the text ``"inf"``, ``"-inf"`` or ``"nan"``, which
    strict JSON holds and a config model reads back as the float (a config value of inf means "no limit": null
    would not read back, and would hash apart from the config it came from)."""
    if isinstance(value, dict | list | tuple):
        return _walk(value, nonfinite_as_text)
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def _walk(container: dict[Any, Any] | list[Any] | tuple[Any, ...], leaf: Callable[[Any], Any]) -> Any:
    """A dict's values or a list's (a tuple's, as a list) each through ``leaf``."""
    if isinstance(container, dict):
        return {k: leaf(v) for k, v in container.items()}
    return [leaf(v) for v in container]
