"""The parameters a ROS 1 launch file (roslaunch XML) gives one node, e.g. amcl's, read with the standard library.

roslaunch's rules (``roslaunch/loader.py``, ``xmlloader.py``), as far as a file alone decides them:

- Every ``<param>`` and ``<rosparam>`` of the file lands on the parameter server under its resolved name: relative
  names join the enclosing ``<group ns>`` (and ``<rosparam ns>``), ``/`` names are global, and inside a ``<node>``
  names are the node's private ones (``/NS/NODE/name``). The node reads ``/NS/NODE/*``, wherever in the file
  they were set; the last setting wins.
- ``<param value type>``: roslaunch's ``convert_value`` (no type: a float when the text holds a ``.``, else an int,
  else ``true``/``false``, else the string). ``<rosparam>``: YAML from its text or ``file``, under ``param`` /
  ``ns``; ``subst_value`` substitutes its text.
- ``<arg name default|value>``: scoped, a ``<group>`` works on a copy; ``value`` sets it, ``default`` only where it
  has no value yet (an include passed one); ``$(arg NAME)``, ``$(env VAR)``, ``$(optenv VAR DEFAULT)``,
  ``$(dirname)`` (the folder of the file that holds it), and ``$(find PKG)`` by ``ROS_PACKAGE_PATH`` (a folder
  holding the ``package.xml`` of that name). ``$(eval ...)``, ``$(anon ...)`` need roslaunch itself: such a value
  is *unresolved* (reported, never guessed), and so is an ``if``/``unless`` that does not resolve (its element is
  left out). Args passed as on roslaunch's command line (``name:=value``, :func:`read_launch_node`'s ``args``) set the
  top file's: its ``default`` yields to them, and one it sets with ``value`` is an error, as in roslaunch; one no
  file declares (the top file, or one it passes all its args to) is an error too, where roslaunch ignores it
  (a typo must not run with the default).
- ``<remap from to>`` inside the node, or before it in an enclosing scope, resolved against the node's namespace.
- ``<include file ns pass_all_args>`` is followed: the file is read under ``ns`` with the args its ``<arg>``
  children pass (and all of the includer's with ``pass_all_args``), the enclosing remaps in force. A file that
  cannot be found or resolved is reported, as an unresolved value is.
"""

from __future__ import annotations

import contextlib
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from doorbatch.errors import ConfigError

_SUBSTITUTION = re.compile(r"\$\((\w+)(?:\s+([^)]*))?\)")
_UNRESOLVED_ARG = "\x00unresolved: "  # an arg whose value needs roslaunch: its uses are unresolved too
_PACKAGE_NAME = re.compile(rb"<name>\s*([^<\s]+)\s*</name>")


class _UnresolvedError(Exception):
    """A substitution only roslaunch or a ROS installation can resolve, or an unknown arg."""


@dataclass(frozen=True)
class LaunchNode:
    """One node as its launch file sets it up."""

    name: str  # resolved, e.g. /robot1/amcl
    params: dict[str, Any] = field(default_factory=dict)  # its private parameters, names relative to it
    remaps: dict[str, str] = field(default_factory=dict)  # resolved name → resolved name
    unresolved: list[str] = field(default_factory=list)  # what was left out, and why
    notes: list[str] = field(default_factory=list)  # values taken from this machine's environment

    def resolve(self, name: str) -> str:
        """The topic the node gets when it asks for ``name`` (relative to its namespace), after remapping."""
        full = _join(self.name.rsplit("/", 1)[0] + "/", name)
        return self.remaps.get(full, full)


@dataclass
class _Scope:
    ns: str  # "/" or "/robot1/"
    args: dict[str, str]
    remaps: dict[str, str]  # from → to as written (substituted): a node resolves them in its own namespace


def _join(ns: str, name: str) -> str:
    """rosgraph.names: a global name as it is, a relative one under ``ns`` (which ends with ``/``)."""
    name = name.strip()
    return name if name.startswith("/") else ns + name


def _ns(ns: str, name: str | None) -> str:
    """The namespace ``name`` (relative to ``ns``) with a trailing ``/``."""
    return ns if not name else _join(ns, name).rstrip("/") + "/"


@cache
def _packages(roots: str) -> dict[str, Path]:
    """Package name → folder under the ``ROS_PACKAGE_PATH`` roots (rospack: a package.xml stops the descent)."""
    found: dict[str, Path] = {}
    for root in filter(None, roots.split(os.pathsep)):
        for folder, dirs, files in os.walk(root):
            if "package.xml" in files:
                match = _PACKAGE_NAME.search(Path(folder, "package.xml").read_bytes())
                found.setdefault(match.group(1).decode() if match else Path(folder).name, Path(folder))
                dirs.clear()
    return found


# Includes deeper than this are taken for a cycle (roslaunch itself recurses until Python's limit).
MAX_INCLUDE_DEPTH = 16


class _Reader:
    def __init__(self, path: Path, parent: _Reader | None = None) -> None:
        """A reader of ``path``; one ``parent`` shares its parameter server, nodes and reports (an include)."""
        self.path = path
        self.folder = path.resolve().parent
        self.depth: int = 0 if parent is None else parent.depth + 1
        self.params: dict[str, Any] = {} if parent is None else parent.params
        # (resolved name, type, remaps in force)
        self.nodes: list[tuple[str, str, dict[str, str]]] = [] if parent is None else parent.nodes
        self.unresolved: list[str] = [] if parent is None else parent.unresolved
        self.notes: list[str] = [] if parent is None else parent.notes
        self.includes: list[str] = [] if parent is None else parent.includes  # those that could not be read
        self.declared: set[str] = set()  # the <arg> names of this file (and of those it passes all its args to)
        self.passed: frozenset[str] = frozenset()  # the args passed on the command line (the top file's reader)

    def substitute(self, text: str, scope: _Scope) -> str:
        def one(match: re.Match[str]) -> str:
            kind, rest = match.group(1), (match.group(2) or "").strip()
            if kind == "arg":
                if rest not in scope.args:
                    raise _UnresolvedError(f"$(arg {rest}) has no value")
                if scope.args[rest].startswith(_UNRESOLVED_ARG):
                    raise _UnresolvedError(f"$(arg {rest}): {scope.args[rest][len(_UNRESOLVED_ARG):]}")
                return scope.args[rest]
            if kind in ("env", "optenv"):
                name, _, default = rest.partition(" ")
                if name not in os.environ and kind == "env":
                    raise _UnresolvedError(f"$(env {name}) is not set")
                self.notes.append(f"$({kind} {name}) taken from this machine's environment")
                return os.environ.get(name, default)
            if kind == "dirname":
                return str(self.folder)
            if kind == "find":
                package = _packages(os.environ.get("ROS_PACKAGE_PATH", "")).get(rest)
                if package is None:
                    raise _UnresolvedError(f"$(find {rest}) needs ROS_PACKAGE_PATH to hold package {rest!r}")
                return str(package)
            raise _UnresolvedError(f"$({kind} ...) needs roslaunch")

        return _SUBSTITUTION.sub(one, text)

    def enabled(self, element: ET.Element, scope: _Scope) -> bool:
        """roslaunch's ``if`` / ``unless`` (true/1, false/0); one that does not resolve leaves the element out."""
        for attribute, want in (("if", True), ("unless", False)):
            raw = element.get(attribute)
            if raw is None:
                continue
            try:
                value = self.substitute(raw, scope).strip().lower()
            except _UnresolvedError as why:
                self.unresolved.append(f"<{element.tag} {element.get('name') or ''}> left out: {attribute}= {why}")
                return False
            if value not in ("true", "1", "false", "0"):
                raise ConfigError(f"{self.path}: {attribute}={raw!r} is {value!r}, not true/false/1/0")
            if (value in ("true", "1")) != want:
                return False
        return True

    def walk(self, parent: ET.Element, scope: _Scope, node: str | None = None) -> None:
        """Every element of ``parent`` in order; ``node``: the private namespace inside a ``<node>``."""
        base = node or scope.ns
        for element in parent:
            if not self.enabled(element, scope):
                continue
            try:
                self.element(element, scope, base, node)
            except _UnresolvedError as why:
                label = element.get("name") or element.get("param") or element.get("file") or element.tag
                self.unresolved.append(f"{label} ({why})")

    def element(self, element: ET.Element, scope: _Scope, base: str, node: str | None) -> None:
        tag = element.tag
        if tag == "arg" and node is None:
            name = element.get("name", "")
            if name in self.passed and element.get("value") is not None:  # roslaunch's add_arg: already set
                raise ConfigError(f"{self.path}: cannot pass arg {name}: the file sets it with value=")
            self.declared.add(name)
            self.declare_arg(element, scope.args, scope)
        elif tag == "group" and node is None:
            self.walk(element, _Scope(self.namespace(element, scope), dict(scope.args), dict(scope.remaps)))
        elif tag == "include" and node is None:
            self.include(element, scope)
        elif tag == "node" and node is None:
            node_ns = self.namespace(element, scope)
            name = node_ns + self.substitute(element.get("name", element.get("type", "")), scope)
            inner = _Scope(node_ns, scope.args, dict(scope.remaps))
            self.walk(element, inner, name + "/")
            # a remap reaches the node as from:=to, which the node resolves in its own namespace
            remaps = {_join(node_ns, source): _join(node_ns, target) for source, target in inner.remaps.items()}
            self.nodes.append((name, element.get("type", ""), remaps))
        elif tag == "remap" and element.get("from") and element.get("to"):
            source, target = (self.substitute(element.get(k, ""), scope) for k in ("from", "to"))
            scope.remaps[source] = target
        elif tag == "param" and element.get("name"):
            self.param(element, scope, base)
        elif tag == "rosparam" and element.get("command", "load") == "load":
            self.rosparam(element, scope, base)

    def include(self, element: ET.Element, scope: _Scope) -> None:
        """roslaunch's ``<include>``: the file under ``ns``, with the args passed (all with ``pass_all_args``)."""
        raw = element.get("file", "")
        try:
            name = self.substitute(raw, scope)
        except _UnresolvedError as why:
            self.includes.append(raw)
            raise _UnresolvedError(f"<include> not followed: {why}") from None
        path = next((c for c in self.candidates(name) if c.is_file()), None)
        if path is None:
            self.includes.append(name)
            raise _UnresolvedError("<include> not followed: no such file")
        if self.depth >= MAX_INCLUDE_DEPTH:
            raise ConfigError(f"{self.path}: includes nest deeper than {MAX_INCLUDE_DEPTH} (a cycle?) at {name}")
        pass_all = self.substitute(element.get("pass_all_args", "false"), scope).strip().lower() in ("true", "1")
        args = dict(scope.args) if pass_all else {}
        for child in element:  # the include's context: its <arg>s, substituted in the includer's scope
            if child.tag == "arg" and self.enabled(child, scope):
                self.declare_arg(child, args, scope)
        try:
            root = ET.parse(path).getroot()
        except ET.ParseError as err:
            raise ConfigError(f"{path} (included by {self.path}): not a valid launch file (XML): {err}") from err
        reader = _Reader(path, self)
        if pass_all:  # the args it is handed are used (or not) there
            reader.declared = self.declared
        reader.walk(root, _Scope(self.namespace(element, scope), args, dict(scope.remaps)))

    def declare_arg(self, element: ET.Element, args: dict[str, str], scope: _Scope) -> None:
        """roslaunch's ``loader.add_arg`` into ``args``: ``value`` sets it, ``default`` only where nothing was passed;
        substituted in ``scope``. A value that needs roslaunch is kept as unresolved, so that its uses are (rather
        than a default taking its place)."""
        name, raw = element.get("name", ""), element.get("value")
        if raw is None and name not in args:
            raw = element.get("default")
        if raw is None:
            return
        try:
            args[name] = self.substitute(raw, scope)
        except _UnresolvedError as why:
            args[name] = f"{_UNRESOLVED_ARG}{why}"

    def candidates(self, name: str) -> list[Path]:
        """Where a file a launch element names may be: relative names from the working folder (roslaunch), else
        from the launch file's own folder."""
        return [Path(name)] if Path(name).is_absolute() else [Path.cwd() / name, self.folder / name]

    def namespace(self, element: ET.Element, scope: _Scope) -> str:
        """The namespace an element's ``ns`` attribute (substituted, relative to the scope's) opens."""
        return _ns(scope.ns, self.substitute(element.get("ns", ""), scope) or None)

    def param(self, element: ET.Element, scope: _Scope, base: str) -> None:
        name = _join(base, self.substitute(element.get("name", ""), scope))
        if element.get("value") is not None:
            text = self.substitute(element.get("value", ""), scope)
        elif element.get("textfile") is not None:
            text = self.read(self.substitute(element.get("textfile", ""), scope), element)
        else:
            raise _UnresolvedError("command= and binfile= need roslaunch")
        try:
            self.params[name] = convert_value(text, element.get("type", "auto"))
        except ValueError as err:
            raise ConfigError(f"{self.path}: <param name=\"{element.get('name')}\">: {err}") from err

    def rosparam(self, element: ET.Element, scope: _Scope, base: str) -> None:
        where = _ns(base, self.substitute(element.get("ns", ""), scope) or None)
        file = element.get("file")
        if file is not None:
            try:
                text = self.read(self.substitute(file, scope), element)
            except _UnresolvedError as why:
                raise ConfigError(f"{self.path}: <rosparam file=\"{file}\">: {why}; set it, or give that YAML file "
                                  "as --config") from None
        else:
            text = element.text or ""
            if element.get("subst_value", "false").lower() in ("true", "1"):
                text = self.substitute(text, scope)
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as err:
            raise ConfigError(f"{self.path}: <rosparam>: not valid YAML: {' '.join(str(err).split())}") from err
        key = element.get("param")
        if key:
            self.store(_join(where, self.substitute(key, scope)), data)
        elif isinstance(data, dict):
            for k, v in data.items():
                self.store(_join(where, str(k)), v)
        elif data is not None:
            raise ConfigError(f"{self.path}: <rosparam> without param= must hold a mapping, got "
                              f"{type(data).__name__}")

    def store(self, name: str, value: Any) -> None:
        """A value on the server; a mapping sets one parameter per leaf (``rosparam load``)."""
        if isinstance(value, dict):
            for k, v in value.items():
                self.store(f"{name}/{k}", v)
        else:
            self.params[name] = value

    def read(self, name: str, element: ET.Element) -> str:
        """The text of a file a launch element names (:meth:`candidates`)."""
        for candidate in self.candidates(name):
            with contextlib.suppress(OSError):
                return candidate.read_text()
        raise ConfigError(f"{self.path}: <{element.tag}> cannot read {name}")


def convert_value(value: str, kind: str) -> Any:
    """A ``<param>`` value as roslaunch's ``convert_value`` types it.

    Raises:
        ValueError: the text is not of the type, or the type is unknown.
    """
    kind = kind.lower()
    if kind == "auto":
        with contextlib.suppress(ValueError):
            return float(value) if "." in value else int(value)
        return value.lower() == "true" if value.lower() in ("true", "false") else value
    if kind in ("str", "string"):
        return value
    if kind == "int":
        return int(value)
    if kind == "double":
        return float(value)
    if kind in ("bool", "boolean"):
        text = value.strip().lower()
        if text in ("true", "1", "false", "0"):
            return text in ("true", "1")
        raise ValueError(f"{value!r} is not a {kind}")
    if kind == "yaml":
        try:
            return yaml.safe_load(value)
        except yaml.YAMLError as err:
            raise ValueError(f"not valid YAML: {' '.join(str(err).split())}") from err
    raise ValueError(f"unknown type {kind!r}")


def read_launch_node(path: Path, node_type: str, args: Mapping[str, str] | None = None) -> LaunchNode:
    """The private parameters, remaps and unresolved values of the one node of ``node_type`` in ``path``.

    Args:
        path: The launch file.
        node_type: The node's ``type``, e.g. ``amcl``.
        args: The top file's args, as ``roslaunch FILE name:=value`` passes them.

    Raises:
        ConfigError: unreadable or not XML; no such node, or more than one; a value of the wrong type; a
            ``<rosparam file>`` that cannot be found or resolved; a passed arg that no file declares (the top file,
            or one it passes all its args to), or that the top file sets with ``value``.
    """
    try:
        root = ET.parse(path).getroot()
    except OSError as err:
        raise ConfigError(f"{path}: cannot read launch file: {err.strerror or err}") from err
    except ET.ParseError as err:
        raise ConfigError(f"{path}: not a valid launch file (XML): {err}") from err
    passed = dict(args or {})
    reader = _Reader(path)
    reader.passed = frozenset(passed)
    reader.walk(root, _Scope("/", passed, {}))
    unused = sorted(set(passed) - reader.declared)
    if unused:  # roslaunch ignores them; here a typo must not run with the default
        declared = ", ".join(sorted(reader.declared - {""})) or "none"
        raise ConfigError(f"{path}: unused args {', '.join(unused)} (the file declares: {declared})")
    wanted = [(name, remaps) for name, kind, remaps in reader.nodes if kind == node_type]
    if not wanted:
        hint = (f"; it includes {', '.join(reader.includes)}, which could not be read: give the file that holds the "
                "node, or set ROS_PACKAGE_PATH") if reader.includes else ""
        raise ConfigError(f"{path}: no <node type=\"{node_type}\"> in this launch file{hint}")
    if len(wanted) > 1:
        raise ConfigError(f"{path}: {len(wanted)} <node type=\"{node_type}\"> ({', '.join(n for n, _ in wanted)}); "
                          "keep one")
    name, remaps = wanted[0]
    prefix = name + "/"
    params = {k[len(prefix):]: v for k, v in reader.params.items() if k.startswith(prefix)}
    return LaunchNode(name, params, remaps, reader.unresolved, sorted(set(reader.notes)))


def is_launch_file(path: Path) -> bool:
    """Whether ``path`` is a roslaunch XML file: a ``.launch`` or ``.xml`` name, or text that opens with ``<``."""
    if path.suffix.lower() in (".launch", ".xml"):
        return True
    try:
        with path.open("rb") as f:
            return f.read(256).lstrip().startswith(b"<")
    except OSError:
        return False
