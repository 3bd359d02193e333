"""The sensor model of paper 001 Sec. III and the E-step of Sec. V (eq. 7).

For beam k the first object along its ray is at distance δ (∞ when the ray meets none). With the validity
variable v (prior p(v = 1) = λ):

    p(d | v = 1) = α N(d; min(dmax, δ), σ²),   α = 1 / (Φ((dmax − μ)/σ) − Φ(−μ/σ))  (normalised on [0, dmax])
    p(d | v = 0) = 1 / dmax
    p(l | v = 1) = N(l; μ_C, diag σ²_C)   (C: class of the first object; eq. 3)
    p(l | v = 0) = 1 / 256³               (colour drawn uniformly)

and the E-step's expectation e = p(v = 1 | d, l) ∝ λ p(d | v = 1) p(l | v = 1) (eq. 7). A colour is scored
only when the beam has one and the model puts an object in its way (otherwise both hypotheses are uniform).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.special import log_ndtr

from doorbatch.pipeline.objectmap.beams import BeamSet, beam_blocks
from doorbatch.pipeline.objectmap.colors import class_color_loglik
from doorbatch.pipeline.objectmap.model import DOOR, WALL, ClassParams, ObjectMap
from doorbatch.sim.raycast import RayBuffers, cast_rays

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

LOG_UNIFORM_COLOR = -3.0 * np.log(256.0)
_CHUNK = 16384  # beams per ray-casting call: keeps the (beams × segments) scratch arrays small


@dataclass(frozen=True)
class FirstObjects:
    """Per beam: distance δ to the first object (inf: none), its class (−1: none) and object index."""

    delta: FloatArray
    cls: IntArray
    obj: IntArray

    @staticmethod
    def none(n: int) -> FirstObjects:
        """n beams that meet no object (yet)."""
        return FirstObjects(np.full(n, np.inf), np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64))


def cast_segments(origin: FloatArray, direction: FloatArray, segments: FloatArray,
                  buffers: RayBuffers | None = None) -> tuple[FloatArray, IntArray]:
    """First hit of each ray (origin (N, 2), unit direction (N, 2)) among ``segments`` (S, 2, 2), in chunks."""
    n = origin.shape[0]
    rng = np.full(n, np.inf)
    idx = np.full(n, -1, dtype=np.int64)
    if segments.shape[0] == 0 or n == 0:
        return rng, idx
    buf = buffers or RayBuffers()
    for sl in beam_blocks(n, _CHUNK):
        rng[sl], idx[sl] = cast_rays(origin[sl], direction[sl], segments, buf)
    return rng, idx


def first_objects(beams: BeamSet, obj_map: ObjectMap) -> FirstObjects:
    """φ_k and δ_k for every beam: vectorized ray casting against every wall segment and door leaf of the
    beam's pass."""
    n = len(beams)
    delta = np.full(n, np.inf)
    cls = np.full(n, -1, dtype=np.int64)
    obj = np.full(n, -1, dtype=np.int64)
    buf = RayBuffers()
    for t in range(beams.n_passes):
        sel = np.flatnonzero(beams.pass_index == t)
        segs, seg_cls, seg_obj = obj_map.segments(t)
        rng, idx = cast_segments(beams.origin[sel], beams.direction[sel], segs, buf)
        delta[sel] = rng
        got = idx >= 0
        cls[sel[got]] = seg_cls[idx[got]]
        obj[sel[got]] = seg_obj[idx[got]]
    return FirstObjects(delta, cls, obj)


def range_loglik_valid(d: FloatArray, delta: FloatArray, dmax: FloatArray, sigma: float) -> FloatArray:
    """log p(d | v = 1): the Gaussian about min(dmax, δ) normalised on [0, dmax] (Sec. III)."""
    mu = np.minimum(dmax, delta)
    # α⁻¹ = Φ((dmax − μ)/σ) − Φ(−μ/σ); with μ ∈ [0, dmax] the second term is tiny except near 0
    norm = np.exp(log_ndtr((dmax - mu) / sigma)) - np.exp(log_ndtr(-mu / sigma))
    log_alpha = -np.log(np.maximum(norm, 1e-300))
    z = (d - mu) / sigma
    return np.asarray(log_alpha - 0.5 * z * z - np.log(sigma * np.sqrt(2.0 * np.pi)), dtype=np.float64)


def color_loglik(color: FloatArray, cls: IntArray, classes: ClassParams) -> FloatArray:
    """log p(l | v = 1) − log p(l | v = 0) per beam: the class Gaussian (eq. 3) against the uniform colour;
    0 where the beam has no colour, no object is in its way, or the model has no colour."""
    out = np.zeros(cls.shape[0])
    if not classes.has_color:
        return out
    has_color = np.isfinite(color[:, 0])
    for c in (WALL, DOOR):
        ok = has_color & (cls == c)
        out[ok] = class_color_loglik(color[ok], c, classes) - LOG_UNIFORM_COLOR
    return out


def beam_logliks(beams: BeamSet, delta: FloatArray, cls: IntArray, classes: ClassParams, lam: float,
                 sigma: float) -> tuple[FloatArray, FloatArray]:
    """(log λ p(d, l | v = 1), log (1 − λ) p(d, l | v = 0)) per beam, with the uniform colour density
    factored out of both (it cancels in e and in every comparison)."""
    valid = np.log(lam) + range_loglik_valid(beams.range_m, delta, beams.dmax, sigma)
    valid = valid + color_loglik(beams.color, cls, classes)
    invalid = np.log1p(-lam) - np.log(beams.dmax)
    return valid, np.asarray(invalid, dtype=np.float64)


def e_step(beams: BeamSet, first: FirstObjects, classes: ClassParams, lam: float, sigma: float
           ) -> tuple[FloatArray, FloatArray]:
    """Eq. (7): e_k = p(v_k = 1 | d_k, l_k, map) and the per-beam marginal log-likelihood
    log Σ_v p(d, l, v) (up to the constant uniform colour term). In blocks of beams (per-beam values, so
    the same as one pass over all), to bound the scratch memory on long logs."""
    e = np.empty(len(beams))
    total = np.empty(len(beams))
    for sl in beam_blocks(len(beams)):
        valid, invalid = beam_logliks(beams.subset(sl), first.delta[sl], first.cls[sl], classes, lam, sigma)
        total[sl] = np.logaddexp(valid, invalid)
        e[sl] = np.exp(valid - total[sl])
    return e, total
