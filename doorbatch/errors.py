"""The exceptions doorbatch raises for bad input, and the exit codes the CLI maps them to.

One root, :class:`DoorbatchError`, one subclass per layer. Library code raises these (``raise ... from
err`` at layer boundaries); only ``doorbatch.cli`` turns them into a one-line message and an exit code.
"""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    """Process exit codes fixed by DESIGN.md."""

    OK = 0
    USAGE = 2  # usage or config error
    BAD_INPUT = 3  # bad input data: the message names the file, topic and what is wrong
    PARTIAL = 4  # a batch finished with some logs failed and the rest complete


class DoorbatchError(Exception):
    """Root of every error doorbatch raises on purpose."""

    exit_code: ExitCode = ExitCode.BAD_INPUT


class ConfigError(DoorbatchError):
    """A config file, key or value is wrong (unknown key, wrong type, bad YAML)."""

    exit_code = ExitCode.USAGE


class UsageError(DoorbatchError):
    """Command-line arguments that do not fit together."""

    exit_code = ExitCode.USAGE


class InputDataError(DoorbatchError):
    """Bad input data. Carries the file and, when known, the topic, so the one-line message names both."""

    def __init__(self, message: str, *, path: object | None = None, topic: str | None = None) -> None:
        self.path = None if path is None else str(path)
        self.topic = topic
        self.reason = message
        where = []
        if self.path is not None:
            where.append(self.path)
        if topic is not None:
            where.append(f"topic {topic}")
        prefix = ": ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class LogReadError(InputDataError):
    """A log cannot be opened or read: unknown format, empty, truncated, corrupt."""


class LogContentError(InputDataError):
    """A log reads but its content is unusable: no scan, ranges length ≠ angle count, stamps going
    backwards, a missing transform."""


class LaserMountError(LogContentError):
    """No transform takes the laser's frame to the robot's base (no mount in the log)."""


class TransformError(InputDataError):
    """A transform between two frames is not available at the requested time."""


class PipelineError(DoorbatchError):
    """A stage cannot produce a result from otherwise valid input (e.g. no usable pose source)."""


class BatchPartialError(DoorbatchError):
    """A batch finished with some logs failed and the rest complete."""

    exit_code = ExitCode.PARTIAL


class OutputLockedError(DoorbatchError):
    """Another live run holds the output folder's lock: a usage error (exit 2), not bad data; retry later."""

    exit_code = ExitCode.USAGE


class OptionalDependencyError(DoorbatchError):
    """An optional extra (torch, dask, ...) is needed but not installed."""

    exit_code = ExitCode.USAGE

    def __init__(self, module: str, extra: str) -> None:
        self.module, self.extra = module, extra
        super().__init__(f'{module} is not installed: pip install "doorbatch[{extra}]"')

    def __reduce__(self) -> tuple[type[OptionalDependencyError], tuple[str, str], dict[str, object]]:
        """Rebuilt from its two arguments and its attributes (pickle's default passes the message alone: a process
        pool's worker raising it broke the pool)."""
        return type(self), (self.module, self.extra), self.__dict__
