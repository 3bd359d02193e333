"""The parameters a ROS 1 launch file (roslaunch XML) gives one node, e.g. amcl's, read with the standard library.

roslaunch's rules, as far as a file alone decides them:

- ``<arg name=... default=... | value=...>`` anywhere before use, and ``$(arg NAME)`` in attributes and text;
  ``$(env VAR)`` / ``$(optenv VAR DEFAULT)`` from the environment, ``$(dirname)`` as the file's folder. ``$(find
  PKG)``, ``$(eval ...)`` and the others need a ROS installation: a value holding one is *unresolved* (reported,
  not guessed).
- In the ``<node>`` whose ``type`` is asked for: ``<param name value [type]>`` (no ``type``: ``true``/``false`` is a
  bool, then int, then float, else the string, as roslaunch does), ``<rosparam>`` with YAML text or
  ``file=...`` (``command="load"``; later ones win), and ``<remap from to>``.
- ``<group>`` blocks are entered (their ``if``/``unless`` honoured when they resolve); ``<include>`` is not followed.
"""

from __future__ import annotations

import contextlib
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from doorbatch.errors import ConfigError

_SUBSTITUTION = re.compile(r"\$\((\w+)(?:\s+([^)]*))?\)")


class _UnresolvedError(Exception):
    """A substitution that needs a ROS installation (``$(find ...)``, ``$(eval ...)``) or an unknown arg."""


@dataclass(frozen=True)
class LaunchNode:
    """One node's parameters as its launch file gives them."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)
    remaps: dict[str, str] = field(default_factory=dict)
    unresolved: list[str] = field(default_factory=list)  # parameter names (or rosparam files) left out, and why


def _substitute(text: str, args: dict[str, str], folder: Path) -> str:
    def one(match: re.Match[str]) -> str:
        kind, rest = match.group(1), (match.group(2) or "").strip()
        if kind == "arg":
            if rest not in args:
                raise _UnresolvedError(f"$(arg {rest}) has no value")
            return args[rest]
        if kind == "env":
            if rest not in os.environ:
                raise _UnresolvedError(f"$(env {rest}) is not set")
            return os.environ[rest]
        if kind == "optenv":
            name, _, default = rest.partition(" ")
            return os.environ.get(name, default)
        if kind == "dirname":
            return str(folder)
        raise _UnresolvedError(f"$({kind} ...) needs a ROS installation")

    return _SUBSTITUTION.sub(one, text)


def _typed(value: str, kind: str | None) -> Any:
    """A ``<param>`` value as roslaunch types it."""
    if kind in ("str", "string"):
        return value
    if kind == "yaml":
        return yaml.safe_load(value)
    text = value.strip()
    if kind == "bool" or (kind is None and text.lower() in ("true", "false")):
        return text.lower() == "true"
    for convert in ((int,) if kind == "int" else (float,) if kind == "double" else (int, float) if kind is None
                    else ()):
        try:
            return convert(text)
        except ValueError:
            continue
    if kind in ("int", "double"):
        raise ValueError(f"{value!r} is not {kind}")
    return value


def _enabled(element: ET.Element, args: dict[str, str], folder: Path) -> bool:
    """roslaunch's ``if`` / ``unless`` attributes (true/1, false/0); an unresolvable one counts as true."""
    for attribute, want in (("if", True), ("unless", False)):
        raw = element.get(attribute)
        if raw is None:
            continue
        try:
            value = _substitute(raw, args, folder).strip().lower()
        except _UnresolvedError:
            continue
        if (value in ("true", "1")) != want:
            return False
    return True


def read_launch_node(path: Path, node_type: str) -> LaunchNode:
    """The parameters, remaps and unresolved values of the one node of ``node_type`` in the launch file ``path``.

    Raises:
        ConfigError: unreadable or not XML; no such node, or more than one; a value of the wrong type.
    """
    try:
        root = ET.parse(path).getroot()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read launch file: {err.strerror or err}") from err
    except ET.ParseError as err:
        raise ConfigError(f"{path}: not a valid launch file (XML): {err}") from err
    folder = path.resolve().parent
    args: dict[str, str] = {}
    nodes: list[LaunchNode] = []
    includes: list[str] = []

    def walk(parent: ET.Element) -> None:
        for element in parent:
            if not _enabled(element, args, folder):
                continue
            if element.tag == "arg":
                raw = element.get("value", element.get("default"))
                if raw is not None and element.get("name") not in args:
                    with contextlib.suppress(_UnresolvedError):  # roslaunch would fail; its uses are reported
                        args[element.get("name", "")] = _substitute(raw, args, folder)
            elif element.tag == "group":
                walk(element)
            elif element.tag == "include":
                includes.append(element.get("file", "?"))
            elif element.tag == "node" and element.get("type") == node_type:
                nodes.append(_node(element, args, folder, path))

    walk(root)
    if not nodes:
        hint = f"; it includes {', '.join(includes)}: give the file that holds the node" if includes else ""
        raise ConfigError(f"{path}: no <node type=\"{node_type}\"> in this launch file{hint}")
    if len(nodes) > 1:
        raise ConfigError(f"{path}: {len(nodes)} <node type=\"{node_type}\"> ({', '.join(n.name for n in nodes)}); "
                          "keep one")
    return nodes[0]


def _node(element: ET.Element, args: dict[str, str], folder: Path, path: Path) -> LaunchNode:
    params: dict[str, Any] = {}
    remaps: dict[str, str] = {}
    unresolved: list[str] = []
    for child in element:
        if not _enabled(child, args, folder):
            continue
        try:
            if child.tag == "param" and child.get("name"):
                raw = child.get("value")
                if raw is None:
                    unresolved.append(f"{child.get('name')} (no value attribute)")
                    continue
                try:
                    params[child.get("name", "")] = _typed(_substitute(raw, args, folder), child.get("type"))
                except ValueError as err:
                    raise ConfigError(f"{path}: <param name=\"{child.get('name')}\">: {err}") from err
            elif child.tag == "rosparam" and child.get("command", "load") == "load":
                params.update(_rosparam(child, args, folder, path))
            elif child.tag == "remap" and child.get("from") and child.get("to"):
                source, target = (_substitute(child.get(k, ""), args, folder) for k in ("from", "to"))
                remaps[source] = target
        except _UnresolvedError as why:
            unresolved.append(f"{child.get('name') or child.get('file') or child.get('from') or child.tag} ({why})")
    return LaunchNode(element.get("name", element.get("type", "")), params, remaps, unresolved)


def _rosparam(element: ET.Element, args: dict[str, str], folder: Path, path: Path) -> dict[str, Any]:
    """A ``<rosparam command="load">``: its file or its text, as a mapping (``param=...`` nests it)."""
    file = element.get("file")
    if file is not None:
        target = Path(_substitute(file, args, folder))
        target = target if target.is_absolute() else folder / target
        try:
            text = target.read_text()
        except OSError as err:
            raise ConfigError(f"{path}: <rosparam file=\"{file}\">: cannot read {target}: {err.strerror or err}"
                              ) from err
    else:
        text = _substitute(element.text or "", args, folder) if element.get("subst_value") == "true" else (
            element.text or "")
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as err:
        raise ConfigError(f"{path}: <rosparam>: not valid YAML: {' '.join(str(err).split())}") from err
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: <rosparam>: expected a mapping of parameters, got {type(data).__name__}")
    name = element.get("param")
    return {name: data} if name else data


def is_launch_file(path: Path) -> bool:
    """Whether ``path`` is a roslaunch XML file: a ``.launch`` or ``.xml`` name, or text that opens with ``<``."""
    if path.suffix.lower() in (".launch", ".xml"):
        return True
    try:
        with path.open("rb") as f:
            return f.read(256).lstrip().startswith(b"<")
    except OSError:
        return False
