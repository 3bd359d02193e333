"""doorbatch: door-aware maps, localization with door states, door poses and metrics from robot logs."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("doorbatch")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
