"""Output folders that appear complete or not at all: a step writes into a hidden temporary folder beside
the destination, which is renamed into place when the step succeeds.

Temporary folders are ``.<name>.<16 hex>.tmp`` (a replaced old folder briefly ``.<name>.<16 hex>.old``);
:func:`remove_leftovers` deletes what a killed run left. Replacing an existing folder takes two renames
(old away, new in); a kill between them leaves the destination missing, never partial, and the next run
redoes that step.
"""

from __future__ import annotations

import re
import secrets
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from doorbatch.errors import UsageError
from doorbatch.io.atomic import TEMP_MARKER

_OLD_MARKER = ".old"


def _sibling(dest: Path, marker: str) -> Path:
    return dest.with_name(f".{dest.name}.{secrets.token_hex(8)}{marker}")


@contextmanager
def staged_dir(dest: Path) -> Iterator[Path]:
    """Yield an empty temporary folder; when the ``with`` body returns it replaces ``dest``.

    When the body raises (or is interrupted), the temporary folder is removed and ``dest`` is untouched.

    Raises:
        OSError: the folder cannot be created or renamed.
    """
    dest = Path(dest)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = _sibling(dest, TEMP_MARKER)
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = _sibling(dest, _OLD_MARKER)
    if dest.exists():
        dest.rename(old)
    tmp.rename(dest)
    shutil.rmtree(old, ignore_errors=True)


@contextmanager
def staged_files(dest: Path) -> Iterator[Path]:
    """Yield an empty temporary folder inside ``dest`` (created where missing) for a command's output files; when
    the ``with`` body returns, each is renamed into ``dest``, replacing an entry of its name, and the temporary
    folder is removed. Other entries of ``dest`` stay (a user's own files). Inside, not beside: ``-o .`` has no
    sibling, a folder the user may write in may sit in one the user may not (``-o ~``), and a mount point
    (a container's ``-o /out``) is another file system than its parent's.

    When the body raises (or is interrupted: Ctrl-C, SIGTERM), the temporary folder is removed, and ``dest`` too
    where this made it: an interrupted command leaves no new folder half written, and no folder with some files of
    the new run beside the rest of the old one (a manifest that does not describe the trajectory beside it).

    Raises:
        OSError: the folder cannot be created, or an entry renamed.
    """
    dest = Path(dest)
    made = not dest.exists()
    dest.mkdir(parents=True, exist_ok=True)
    tmp = dest / f".doorbatch.{secrets.token_hex(8)}{TEMP_MARKER}"
    tmp.mkdir()
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(dest if made else tmp, ignore_errors=True)
        raise
    try:
        for item in sorted(tmp.iterdir()):
            target = dest / item.name
            if item.is_dir() and target.is_dir():
                shutil.rmtree(target)
            item.replace(target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def check_output_location(dest: Path, folder: bool) -> None:
    """Fail early, before any work, where ``dest`` (an output folder, or file) could not be written: a file
    where a folder must go or the other way round, an existing file among its parents, or a folder in which
    nothing can be created: ``dest`` itself when it is an existing folder (commands write inside it), else its
    nearest existing ancestor (where it, or its parent folders, will be created). Creates nothing: the probe
    folder it makes is removed at once.

    Raises:
        UsageError: what is in the way, naming the path.
    """
    dest = Path(dest).absolute()
    if dest.exists() and dest.is_dir() != folder:
        raise UsageError(f"-o {dest}: exists and is {'a file' if folder else 'a folder'}, not "
                         f"{'a folder' if folder else 'a file'}")
    where = dest if folder and dest.is_dir() else next(a for a in dest.parents if a.exists())
    if not where.is_dir():
        raise UsageError(f"-o {dest}: {where} is a file, not a folder")
    try:
        probe = where / f".{dest.name}.{secrets.token_hex(8)}{TEMP_MARKER}"
        probe.mkdir()
        probe.rmdir()
    except OSError as err:
        raise UsageError(f"-o {dest}: cannot write in {where}: {err.strerror or err}") from err


# ``.<name>.<16 hex>.tmp[<suffix>]`` (staged_dir, atomic.temp_path_for) or ``.<name>.<16 hex>.old``: nothing else,
# so that a user's ``.notes.old`` or ``.cache.tmp`` in OUT is never taken for one
_LEFTOVER = re.compile(rf"^\..+\.[0-9a-f]{{16}}({re.escape(TEMP_MARKER)}.*|{re.escape(_OLD_MARKER)})$")


def is_leftover(path: Path) -> bool:
    """Whether ``path`` is a temporary file or folder of :func:`staged_dir` or :mod:`doorbatch.io.atomic`."""
    return _LEFTOVER.match(path.name) is not None


def remove_leftovers(root: Path) -> list[Path]:
    """Delete every temporary file and folder under ``root`` that an interrupted run left; return them.

    Call it only while holding the output's lock (a running step's temporary folder looks the same).
    """
    removed: list[Path] = []
    if not root.is_dir():
        return removed
    stack = [root]
    while stack:
        folder = stack.pop()
        for path in sorted(folder.iterdir()):
            if is_leftover(path):
                if path.is_dir():
                    shutil.rmtree(path, ignore_errors=True)
                else:
                    path.unlink(missing_ok=True)
                removed.append(path)
            elif path.is_dir() and not path.is_symlink():
                stack.append(path)
    return removed
