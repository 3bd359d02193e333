"""When a global localization may claim convergence, and when it must report ambiguity instead.

A cloud that is tight after a few scans of a uniform start is often tight on the wrong pose: a corridor with
similar ends, or closed doors flush with the walls, is symmetric (DESIGN pitfall), and KLD-sampling plus
resampling thin a cloud to one cluster by chance along an axis the scans do not observe. An expert's
detector therefore asks for more than a small covariance:

1. **tight**: weighted position std ≤ ``converged_xy_std_m`` (both axes) and yaw std ≤
   ``converged_yaw_std_deg``;
2. **unimodal**: less than ``ambiguity_min_weight`` of the weight lies outside ``ambiguity_radius_m`` and
   ``ambiguity_yaw_deg`` of the strongest hypothesis (:func:`is_multimodal`);
3. **held**: 1 and 2 have held without a break for ``converged_hold_s`` seconds while the odometry moved the
   robot ``converged_min_travel_m`` (a stationary robot keeps seeing the same scan; a hypothesis that is
   wrong has to survive new views).

The claimed convergence time is the update at which 3 is met (the time a user could act on it). A break of 1–2
suspends the claim: it is restored, with its time, when the cloud is tight and unimodal again where the odometry has
carried the claimed pose (a sparse log's metre-long odometry step spreads a right cloud for an update), and
withdrawn when it comes back elsewhere or never; the claim that stands at the end of the log is the run's.

4. **fits**: a tight, unimodal cloud on the wrong pose of a symmetric corridor passes 1–3 and fits the scans
   as well as the truth would, until the robot nears something the two poses do not share (an end wall the
   estimate then drives through). A cloud that has been tight and unimodal once (since the start or the last
   loss: a uniform start's mean is no pose) is **lost** once, at its mean, under ``lost_min_fit`` of the scan's
   hits lie within ``lost_fit_distance_m`` of the map's occupied cells (:func:`scan_fit`) for ``lost_after_s``,
   whatever its shape by then: the streak and any claim break, and the run may start over from a uniform cloud.
   Or when over ``lost_max_see_through`` of its beams pass through the map's occupied cells on their way to
   their hits (:func:`see_through_share`) for ``lost_after_s``: parallel corridor walls keep the hits of a pose
   shifted along the corridor near walls, but its beams then cross the walls between doorways and the end wall.
   A beam cannot pass through a wall, so at the true pose on a right map few do (glass, a door mapped closed,
   a grazing beam's blur); a map lacking what the robot sees (moved furniture, an erased wall) makes hits fit
   poorly but makes no beam pass through a wall, so the two criteria tell a wrong pose from a wrong map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from doorbatch.config import LocalizeConfig
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import compose, relative, transform_points
from doorbatch.maps import OccupancyMap
from doorbatch.pipeline.localize.likelihood_field import DistanceField, cloud_converged, endpoint_distances
from doorbatch.pipeline.localize.particles import ParticleSet


def _near(pose: npt.NDArray[np.float64], centre: npt.NDArray[np.float64], radius_m: float, yaw_rad: float
          ) -> npt.NDArray[np.bool_]:
    """Which poses lie within ``radius_m`` and ``yaw_rad`` of ``centre``."""
    dyaw = np.abs(wrap_angle(pose[:, 2] - centre[2]))
    return np.asarray((np.hypot(pose[:, 0] - centre[0], pose[:, 1] - centre[1]) <= radius_m) & (dyaw <= yaw_rad))


def is_multimodal(particles: ParticleSet, radius_m: float, yaw_rad: float, min_weight: float) -> bool:
    """Whether at least ``min_weight`` of the weight lies away from the strongest hypothesis: outside
    ``radius_m`` (position) or ``yaw_rad`` (heading) of the heaviest mode (:func:`_heaviest_mode`), e.g. a
    symmetric corridor's pose turned by 180° or shifted by a door spacing. (Of the heaviest particle, before: a 3 %
    particle outweighing each of a 97 % mode's made the cloud "ambiguous".)"""
    w, pose = particles.weight, particles.pose
    # the heaviest mode holds at least what lies near the heaviest particle (one of its candidates): where little
    # lies away from that particle, less lies away from the mode, and the cheap test decides (every tracked update)
    if float(w[~_near(pose, pose[int(np.argmax(w))], radius_m, yaw_rad)].sum()) < min_weight:
        return False
    near = _near(pose, _heaviest_mode(w, pose, radius_m, yaw_rad), radius_m, yaw_rad)
    return float(w[~near].sum()) >= min_weight


def multimodal(particles: ParticleSet, config: LocalizeConfig) -> bool:
    """:func:`is_multimodal` with the ``localize.ambiguity_*`` settings."""
    return is_multimodal(particles, config.ambiguity_radius_m, math.radians(config.ambiguity_yaw_deg),
                         config.ambiguity_min_weight)


MODE_CANDIDATES = 32  # the heaviest particles, and as many spread over the set, tried as the centre of a mode


def _heaviest_mode(w: npt.NDArray[np.float64], pose: npt.NDArray[np.float64], radius_m: float, yaw_rad: float
                   ) -> npt.NDArray[np.float64]:
    """The centre of the hypothesis holding the most weight within ``radius_m`` / ``yaw_rad``, among
    :data:`MODE_CANDIDATES` heaviest particles and as many taken evenly over the set: a mode of many light
    particles outweighs one heavy particle (orebro's note named a 3 % "strongest hypothesis" beside a 92 % one)."""
    heavy = np.argpartition(w, -min(MODE_CANDIDATES, w.size))[-MODE_CANDIDATES:]
    spread = np.linspace(0, w.size - 1, min(MODE_CANDIDATES, w.size)).astype(np.intp)
    candidates = np.unique(np.concatenate([heavy, spread]))
    mass = [float(w[_near(pose, pose[c], radius_m, yaw_rad)].sum()) for c in candidates]
    return np.asarray(pose[candidates[int(np.argmax(mass))]])


def multimodal_note(particles: ParticleSet, config: LocalizeConfig, tracked: bool = True) -> str:
    """A warning for a cloud that :func:`multimodal` calls multimodal: the strongest hypothesis (the heaviest mode,
    :func:`_heaviest_mode`) and the next one (the heaviest particle away from it), each with the weight within
    ``ambiguity_radius_m`` / ``ambiguity_yaw_deg`` of it, and the weight away from the strongest; for a ``tracked``
    run (not a global start, where a symmetric map is the usual cause), the motion noise as the likely cause."""
    w, pose = particles.weight, particles.pose
    radius, yaw = config.ambiguity_radius_m, math.radians(config.ambiguity_yaw_deg)
    best = _heaviest_mode(w, pose, radius, yaw)
    near = _near(pose, best, radius, yaw)
    away = np.flatnonzero(~near)
    other = pose[away[int(np.argmax(w[away]))]] if away.size else best
    share = float(w[_near(pose, other, radius, yaw) & ~near].sum())

    def at(p: npt.NDArray[np.float64]) -> str:
        return f"({p[0]:.2f}, {p[1]:.2f}, {math.degrees(p[2]):.0f}°)"

    cause = ("; a tracked cloud spreads so under motion noise too large for the odometry (localize.alpha1 … alpha4)"
             if tracked else "")
    return (f"ambiguous: the cloud ends multimodal, {float(w[~near].sum()):.0%} of its weight away from its strongest "
            f"hypothesis {at(best)} ({float(w[near].sum()):.0%}); the next is {at(other)} ({share:.0%}). Its mean "
            f"(the trajectory's last pose) may lie between them{cause}")


# Below this many hits a scan's share is too coarse to judge a pose by (0, ½, 1 of two hits): no evidence.
MIN_FIT_HITS = 10


def scan_fit(field: DistanceField, pose: npt.ArrayLike, hits_base: npt.ArrayLike, distance_m: float) -> float:
    """Share of the scan's hits (base_link, (B, 2)) that lie within ``distance_m`` of an occupied cell of the
    map, the robot at ``pose``; NaN (no evidence either way) for a scan of fewer than ``MIN_FIT_HITS`` hits."""
    hits = np.asarray(hits_base, dtype=np.float64).reshape(-1, 2)
    if hits.shape[0] < MIN_FIT_HITS:
        return math.nan
    return float(np.mean(endpoint_distances(field, np.asarray(pose, dtype=np.float64).reshape(1, 3), hits)[0]
                         <= distance_m))


def fits(fit: float, through: float, config: LocalizeConfig) -> bool:
    """Whether a scan fits the map at a pose (criterion 4): enough hits near walls, few beams through them
    (NaN, no evidence, fits)."""
    return not (fit < config.lost_min_fit or through > config.lost_max_see_through)


def see_through_share(occ: OccupancyMap, field: DistanceField, pose: npt.ArrayLike, origin_base: npt.ArrayLike,
                      hits_base: npt.ArrayLike, margin_m: float, occupied_at_least: int, max_beams: int) -> float:
    """Share of the scan's beams that pass through an occupied cell of the map more than ``margin_m`` before
    their hit and end farther than ``margin_m`` from any (``field``), the robot at ``pose`` (criterion 4); NaN
    for a scan of fewer than ``MIN_FIT_HITS`` hits.

    Each beam runs from the laser's origin (base_link, (2,)) to its hit (base_link, (B, 2)); it is sampled every
    half cell up to r − margin_m and passes through a wall where a sample's cell holds at least
    ``occupied_at_least`` (unknown cells and the grid's outside hold nothing). A beam that passes a wall and
    ends on another says the crossed one is not there now (a door mapped closed and open now, a wall mapped twice
    or a few centimetres off, which a grazing beam crosses): only a beam ending where the map has nothing
    contradicts the pose. At most ``max_beams`` beams, evenly spread over the scan, are cast.
    """
    hits = np.asarray(hits_base, dtype=np.float64).reshape(-1, 2)
    if hits.shape[0] < MIN_FIT_HITS:
        return math.nan
    if hits.shape[0] > max_beams:
        hits = hits[np.linspace(0, hits.shape[0] - 1, max_beams).round().astype(np.intp)]
    p = np.asarray(pose, dtype=np.float64).reshape(3)
    origin = transform_points(p, origin_base)[0]
    ray = transform_points(p, hits) - origin
    reach = np.hypot(ray[:, 0], ray[:, 1]) - margin_m  # samples up to here may not meet a wall
    if not np.any(reach > 0.0):
        return 0.0
    step = occ.resolution_m / 2.0
    t = step * np.arange(int(np.ceil(float(reach.max()) / step)))
    start = occ.world_to_grid(origin)  # fractional [row, column]; the samples' cells are their floors
    unit = occ.world_to_grid(ray / np.hypot(ray[:, 0], ray[:, 1])[:, None], direction=True)  # (B, 2) cells per m
    rows = np.floor(start[0] + unit[:, :1] * t).astype(np.intp)  # (B, T)
    cols = np.floor(start[1] + unit[:, 1:] * t).astype(np.intp)
    inside = (rows >= 0) & (rows < occ.height) & (cols >= 0) & (cols < occ.width) & (t < reach[:, None])
    occupied = occ.occupancy >= occupied_at_least
    wall = occupied[np.clip(rows, 0, occ.height - 1), np.clip(cols, 0, occ.width - 1)] & inside
    off_walls = endpoint_distances(field, p.reshape(1, 3), hits)[0] > margin_m
    return float(np.mean(wall.any(axis=1) & off_walls))


@dataclass(frozen=True)
class ConvergenceMonitor:
    """The detector's state between updates.

    Attributes:
        since_ns: stamp of the first update of the current tight-and-unimodal streak (None: no streak).
        travel_m: odometry path length since then.
        last_odom: (3,) odometry pose at the previous update (None before the first).
        converged_ns: stamp at which the current streak's convergence was claimed (None: no claim stands).
        poor_fit_since_ns: stamp of the first update of the current run of poor fits (None: the last one fit).
        settled: the cloud has been tight and unimodal since the start or the last loss; only then is a poor fit
            counted (a uniform start's mean is no pose).
        lost: this update found the cloud lost (criterion 4): the caller may start it over.
        suspended_ns: a claim the cloud's spreading or splitting has suspended (None: none is).
        anchor: (mean pose, odometry pose) at the last tight update of the claimed streak.
        claim_since_ns: the first update of the claimed (or suspended) claim's streak: the cloud tight since.
    """

    since_ns: int | None = None
    travel_m: float = 0.0
    last_odom: npt.NDArray[np.float64] | None = None
    converged_ns: int | None = None
    poor_fit_since_ns: int | None = None
    settled: bool = False
    lost: bool = False
    suspended_ns: int | None = None
    anchor: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None = None
    claim_since_ns: int | None = None

    def update(self, stamp_ns: int, odom: npt.ArrayLike, particles: ParticleSet, config: LocalizeConfig,
               fit: float = 1.0, through: float = 0.0, mean: npt.ArrayLike | None = None) -> ConvergenceMonitor:
        """The state after one filter update, whose scan fits the map as ``fit`` and ``through`` say
        (:func:`scan_fit` and :func:`see_through_share` at the cloud's mean; NaN: no evidence); ``mean``: the
        cloud's weighted mean pose when the caller has it (else computed).

        A claim is suspended while the cloud is spread or split. It is restored, with its first stamp, when the cloud
        is tight and unimodal again on the same hypothesis: within ``ambiguity_radius_m`` and ``ambiguity_yaw_deg`` of
        where the odometry has carried the claimed pose since (a sparse log's 1 m odometry step, or a scan that sees
        little, spreads a right cloud for an update or two). Elsewhere, a new streak must hold again. A claim is
        withdrawn for good when the cloud is lost (a hypothesis the scans went on to contradict was not a
        convergence)."""
        o = np.asarray(odom, dtype=np.float64).reshape(3)
        step = 0.0 if self.last_odom is None else float(np.hypot(*(o[:2] - self.last_odom[:2])))
        tight = cloud_converged(particles.weight, particles.pose, config) and not multimodal(particles, config)
        settled = self.settled or tight
        if math.isnan(fit):  # no evidence: a run of poor fits neither ends nor starts here
            poor = self.poor_fit_since_ns if settled else None
        else:
            poor = None if fits(fit, through, config) or not settled else (
                stamp_ns if self.poor_fit_since_ns is None else self.poor_fit_since_ns)
        if poor is not None and (stamp_ns - poor) / 1e9 >= config.lost_after_s:
            return ConvergenceMonitor(None, 0.0, o, None, None, False, lost=True)
        claim = self.converged_ns if self.converged_ns is not None else self.suspended_ns
        kept = self.claim_since_ns if claim is not None else None
        if not tight:
            return ConvergenceMonitor(None, 0.0, o, None, poor, settled, suspended_ns=claim,
                                      anchor=self.anchor if claim is not None else None, claim_since_ns=kept)
        anchor = (particles.mean_and_covariance()[0] if mean is None else np.asarray(mean, dtype=np.float64), o)
        if self.converged_ns is not None:
            return ConvergenceMonitor(self.since_ns, self.travel_m + step, o, self.converged_ns, poor, settled,
                                      anchor=anchor, claim_since_ns=kept)
        same = claim is not None and self.anchor is not None and same_hypothesis(self.anchor, anchor, config)
        if same and poor is None:
            return ConvergenceMonitor(stamp_ns, 0.0, o, claim, poor, settled, anchor=anchor, claim_since_ns=kept)
        since = stamp_ns if self.since_ns is None else self.since_ns
        travel = 0.0 if self.since_ns is None else self.travel_m + step
        held = (stamp_ns - since) / 1e9 >= config.converged_hold_s and travel >= config.converged_min_travel_m
        claimed = stamp_ns if held and poor is None else None
        return ConvergenceMonitor(since, travel, o, claimed, poor, settled, suspended_ns=claim if same else None,
                                  anchor=anchor if claimed is not None or same else None,
                                  claim_since_ns=since if claimed is not None else kept if same else None)


def same_hypothesis(before: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]],
                    now: tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]], config: LocalizeConfig) -> bool:
    """Whether the mean ``now`` (mean pose, odometry pose) lies within ``ambiguity_radius_m`` and
    ``ambiguity_yaw_deg`` of the mean ``before`` carried by the odometry's motion since."""
    predicted = compose(before[0], relative(before[1], now[1]))
    d = now[0] - predicted
    return bool(math.hypot(d[0], d[1]) <= config.ambiguity_radius_m
                and abs(float(wrap_angle(d[2]))) <= math.radians(config.ambiguity_yaw_deg))
