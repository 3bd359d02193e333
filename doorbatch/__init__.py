"""doorbatch: door-aware maps, localization with door states, door poses and metrics from robot logs.

The library calls of a notebook (README, "Library use"), imported on first use so that ``import doorbatch``
stays cheap::

    config = doorbatch.load_config()                 # the defaults; or load_config(Path("my.yaml"), ["k.x=1"])
    door_map = doorbatch.build_map(["pass1.mcap", "pass2.mcap"], config)
    result = doorbatch.localize("run.mcap", door_map, config, method="rbpf")
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # what type checkers and editors see of the lazy names below
    from doorbatch.config import DoorbatchConfig, load_config
    from doorbatch.pipeline.localize.run import load_localization_map, localize
    from doorbatch.pipeline.mapping import build_map

try:
    __version__ = version("doorbatch")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

_LAZY = {
    "load_config": "doorbatch.config",
    "DoorbatchConfig": "doorbatch.config",
    "build_map": "doorbatch.pipeline.mapping",
    "localize": "doorbatch.pipeline.localize.run",
    "load_localization_map": "doorbatch.pipeline.localize.run",
}

__all__ = ["DoorbatchConfig", "__version__", "build_map", "load_config", "load_localization_map", "localize"]


def __getattr__(name: str) -> Any:
    """The library calls of :data:`_LAZY`, imported when first asked for (PEP 562)."""
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'doorbatch' has no attribute {name!r}")


def __dir__() -> list[str]:
    """The package's names, the lazy ones too (tab completion in a notebook)."""
    return sorted({*globals(), *__all__})
