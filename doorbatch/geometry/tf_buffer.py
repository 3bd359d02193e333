"""A TF buffer: static and dynamic transforms, lookups through the frame tree, interpolation in time.

Each child frame has one parent (as in tf2). A dynamic edge keeps its stamped transforms sorted by
time; a lookup at time t interpolates translation linearly and rotation by slerp between the two
neighbouring stamps, and clamps to the end stamp within ``extrapolation_limit_ns`` (tf2 would refuse).
A sensor-mount lookup (``hold_constant``) takes a dynamic edge whose every transform is the same (a mount
logged once, or again and again, on a dynamic topic: writers without ROS's /tf_static do so, and Foxglove
clamps such lookups) as holding at any time; a pose lookup keeps the limit, so that no pose is made up
where the edge has no data.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from doorbatch.errors import TransformError
from doorbatch.geometry.rotations import FloatArray, invert_transform, slerp, transform_matrices, transform_matrix
from doorbatch.records import Transform

_STILL_M = 1e-6  # a dynamic edge whose translation spans less than this (m) ...
_STILL_TURN = 1e-12  # ... and whose rotation 1 − |q·q₀| stays below this (~3 µrad) does not move


@dataclass
class _Edge:
    parent: str
    static: bool
    stamps: list[int] = field(default_factory=list)
    translations: list[FloatArray] = field(default_factory=list)
    rotations: list[FloatArray] = field(default_factory=list)
    log_times: list[int] = field(default_factory=list)  # when the log recorded each (0: not known)
    constant: bool = True  # every transform added so far is the same

    def add(self, tf: Transform) -> None:
        if self.translations and not (np.array_equal(tf.translation, self.translations[0])
                                      and np.array_equal(tf.rotation_xyzw, self.rotations[0])):
            self.constant = False
        i = bisect.bisect_right(self.stamps, tf.stamp_ns)
        if i > 0 and self.stamps[i - 1] == tf.stamp_ns:
            self.translations[i - 1], self.rotations[i - 1] = tf.translation, tf.rotation_xyzw
            self.log_times[i - 1] = tf.log_time_ns
            return
        self.stamps.insert(i, tf.stamp_ns)
        self.translations.insert(i, tf.translation)
        self.rotations.insert(i, tf.rotation_xyzw)
        self.log_times.insert(i, tf.log_time_ns)

    def at(self, stamp_ns: int, limit_ns: int, child: str, hold_constant: bool = False) -> FloatArray:
        if self.static or (hold_constant and self.constant):
            return transform_matrix(self.translations[-1], self.rotations[-1])
        stamps = self.stamps
        i = bisect.bisect_left(stamps, stamp_ns)
        if i < len(stamps) and stamps[i] == stamp_ns:
            return transform_matrix(self.translations[i], self.rotations[i])
        if i == 0 or i == len(stamps):
            end = 0 if i == 0 else len(stamps) - 1
            if abs(stamps[end] - stamp_ns) > limit_ns:
                span = f"[{stamps[0] / 1e9:.3f}, {stamps[-1] / 1e9:.3f}] s"
                raise TransformError(
                    f"transform {self.parent}→{child} requested at {stamp_ns / 1e9:.3f} s, outside {span}"
                )
            return transform_matrix(self.translations[end], self.rotations[end])
        t0, t1 = stamps[i - 1], stamps[i]
        f = (stamp_ns - t0) / (t1 - t0)
        trans = (1.0 - f) * self.translations[i - 1] + f * self.translations[i]
        return transform_matrix(trans, slerp(self.rotations[i - 1], self.rotations[i], f))


class TfBuffer:
    """Holds a log's transforms and answers ``lookup(target, source, stamp_ns)``."""

    def __init__(self, extrapolation_limit_ns: int = 100_000_000) -> None:
        self.extrapolation_limit_ns = extrapolation_limit_ns
        self._edges: dict[str, _Edge] = {}

    def add(self, tf: Transform) -> None:
        """Insert one transform (a static one replaces an earlier static one of the same child)."""
        edge = self._edges.get(tf.child)
        if edge is None or edge.parent != tf.parent or edge.static != tf.static:
            edge = _Edge(tf.parent, tf.static)
            self._edges[tf.child] = edge
        if tf.static:
            edge.stamps, edge.translations, edge.rotations = [tf.stamp_ns], [tf.translation], [tf.rotation_xyzw]
            edge.log_times = [tf.log_time_ns]
        else:
            edge.add(tf)

    @property
    def frames(self) -> set[str]:
        """Every frame named by a transform."""
        return set(self._edges) | {e.parent for e in self._edges.values()}

    def edges(self) -> list[tuple[str, str, bool]]:
        """(parent, child, static) for every edge."""
        return [(e.parent, child, e.static) for child, e in self._edges.items()]

    def static_transforms(self) -> list[Transform]:
        """Every static edge as a transform (a log's sensor mounts, as /tf_static holds them)."""
        return [Transform(stamp_ns=0, parent=e.parent, child=child, translation=e.translations[-1],
                          rotation_xyzw=e.rotations[-1], static=True)
                for child, e in self._edges.items() if e.static]

    def is_static(self, child: str) -> bool:
        """Whether the edge into ``child`` is static (KeyError: ``child`` has no parent)."""
        return self._edges[child].static

    def moves(self, child: str) -> bool:
        """Whether the edge into ``child`` is dynamic and its transform changes over the log (a fixed mount
        republished on /tf, as a ROS 1 robot_state_publisher does, is dynamic but does not move)."""
        edge = self._edges[child]
        if edge.static or edge.constant:
            return False
        trans, rot = np.asarray(edge.translations), np.asarray(edge.rotations)
        turned = 1.0 - np.abs(rot @ rot[0]) / (np.linalg.norm(rot, axis=1) * np.linalg.norm(rot[0]))  # q ≡ −q
        return bool(np.ptp(trans, axis=0).max() > _STILL_M or turned.max() > _STILL_TURN)

    def stamps(self, child: str) -> list[int]:
        """The stamps (ns, sorted) of the edge into ``child`` (KeyError: ``child`` has no parent)."""
        return list(self._edges[child].stamps)

    def log_times(self, child: str) -> list[int]:
        """When the log recorded each transform of :meth:`stamps` (ns; 0 where not known)."""
        return list(self._edges[child].log_times)

    def samples(self, child: str) -> tuple[npt.NDArray[np.int64], FloatArray]:
        """The edge into ``child`` as recorded: its stamps (N,) and 4×4 transforms (N, 4, 4), each what
        :meth:`lookup` gives at that stamp (KeyError: ``child`` has no parent)."""
        edge = self._edges[child]
        return np.asarray(edge.stamps, dtype=np.int64), transform_matrices(np.asarray(edge.translations),
                                                                           np.asarray(edge.rotations))

    def chain(self, frame: str) -> list[str]:
        """``frame`` and its ancestors up to the root of its tree, child first.

        Raises:
            TransformError: the tree has a cycle.
        """
        chain = [frame]
        seen = {frame}
        while chain[-1] in self._edges:
            parent = self._edges[chain[-1]].parent
            if parent in seen:
                raise TransformError(f"transform tree has a cycle through {parent}")
            chain.append(parent)
            seen.add(parent)
        return chain

    def can_transform(self, target: str, source: str) -> bool:
        """Whether the two frames are connected (ignoring time)."""
        if target == source:
            return True
        return bool(set(self.chain(target)) & set(self.chain(source)))

    def lookup(self, target: str, source: str, stamp_ns: int, hold_constant: bool = False) -> FloatArray:
        """4×4 transform taking points in ``source`` to ``target`` at ``stamp_ns``; ``hold_constant``: a sensor
        mount's lookup, for which a dynamic edge that never changed holds at any time.

        Raises:
            TransformError: the frames are not connected, or a dynamic edge has no data near the time.
        """
        if target == source:
            return np.eye(4)
        up_src, up_tgt = self.chain(source), self.chain(target)
        common = next((f for f in up_src if f in set(up_tgt)), None)
        if common is None:
            raise TransformError(f"no transform from frame {source!r} to {target!r}")
        src_to_common = np.eye(4)
        for child in up_src[: up_src.index(common)]:
            src_to_common = self._edges[child].at(stamp_ns, self.extrapolation_limit_ns, child,
                                                  hold_constant) @ src_to_common
        tgt_to_common = np.eye(4)
        for child in up_tgt[: up_tgt.index(common)]:
            tgt_to_common = self._edges[child].at(stamp_ns, self.extrapolation_limit_ns, child,
                                                  hold_constant) @ tgt_to_common
        return invert_transform(tgt_to_common) @ src_to_common
