"""The door-angle prior of the RBPF's global phase: a door is closed or somewhere open.

While the pose is global (``global_door_term``), a particle's door that no observation has reached yet is
weighed under a prior over its angle a (relative to closed_yaw, range [lo, hi] of width Δ, which holds the
closed angle 0: ``door_geometry.with_closed_in_range``), not under the particle's one Gaussian. Doors are mostly
either shut or standing open at some angle, so the prior is the mixture

    p(a) = p_c·N(a; 0, σ_c²) + (1 − p_c)·U(a; lo, hi)

(``global_door_closed_prob`` p_c, ``global_door_closed_sigma_deg`` σ_c: the closed leaf's spread about the map's
closed direction). p_c = 0 is the uniform prior of branch loc5, which tracking uses (``tracking_door_prior``). The
paper gives no prior for the global phase.

For a linear-Gaussian angle measurement z ~ N(a, R) (the Douglas–Peucker leaf, or the beams on a leaf combined:
``rbpf.condition_doors_on_beams``) both the evidence and the posterior are in closed form:

    p(z) = p_c·N(z; 0, σ_c² + R) + (1 − p_c)·[Φ((hi − z)/√R) − Φ((lo − z)/√R)] / Δ       (:func:`log_evidence`)

and the posterior is the mixture of N(K·z, K·R), K = σ_c²/(σ_c² + R) (closed) and N(z, R) truncated to [lo, hi]
(open), weighed by each component's share of p(z). The particle carries one Gaussian per door, so the posterior
is moment-matched into it (:func:`posterior`): a clear measurement picks its component (the other's weight is
negligible), an ambiguous one keeps the spread of both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.special import log_ndtr

from doorbatch.config import LocalizeConfig
from doorbatch.maps import DoorSet

FloatArray = npt.NDArray[np.float64]

_NARROW_RAD = 1e-9  # a range narrower than this is a point: the open component is N(z; lo, R)
_MIN_VAR = 1e-12  # rad²; floor of a posterior variance (a point range's truncated normal has none)


@dataclass(frozen=True)
class DoorPrior:
    """The mixture prior's two numbers: the probability of the closed component and its variance (rad²)."""

    closed_prob: float
    closed_var: float

    @classmethod
    def from_config(cls, config: LocalizeConfig) -> DoorPrior:
        """``global_door_closed_prob`` and ``global_door_closed_sigma_deg``² (in rad²)."""
        return cls(config.global_door_closed_prob, math.radians(config.global_door_closed_sigma_deg) ** 2)


UNIFORM = DoorPrior(0.0, 0.0)


def unobserved_door_variance(doors: DoorSet, config: LocalizeConfig) -> FloatArray:
    """(D,) the variance from which on a particle's door counts as not yet observed: the uniform prior's over
    the door's range, Δ²/12 (the Gaussian that moment-matches it), or the start / cap variance
    ``door_init_sigma_deg``² when that is smaller (the random walk never lets a door exceed it).

    A tracked or mid-range start is at or above it until the door update has seen the door; a door unseen for
    long returns to it through the random walk (its angle is then as unknown as at the start; with the default
    0.01 rad/√s that takes about half an hour for a 90° range: a door that moves meanwhile is caught by the update's
    moved-door gate instead, door_observation.kalman_update).
    """
    width = np.asarray(doors.angle_max, dtype=np.float64) - np.asarray(doors.angle_min, dtype=np.float64)
    out: FloatArray = np.minimum(width**2 / 12.0, math.radians(config.door_init_sigma_deg) ** 2)
    return out


def log_normal(x: FloatArray, mean: FloatArray | float, var: FloatArray | float) -> FloatArray:
    """log N(x; mean, var), elementwise."""
    return np.asarray(-0.5 * (x - mean) ** 2 / var - 0.5 * np.log(2 * math.pi * var), dtype=np.float64)


def _log_mass(alpha: FloatArray, beta: FloatArray) -> FloatArray:
    """log(Φ(β) − Φ(α)) for α ≤ β, stable in both tails (reflected so that the smaller tail is differenced)."""
    flip = alpha > 0.0
    a = np.where(flip, -beta, alpha)
    b = np.where(flip, -alpha, beta)
    lb, la = log_ndtr(b), log_ndtr(a)
    with np.errstate(divide="ignore"):
        out: FloatArray = lb + np.log1p(-np.exp(np.minimum(la - lb, 0.0)))
    return out


def _open_component(z: FloatArray, meas_var: FloatArray, lo: FloatArray, hi: FloatArray
                    ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The uniform component: log of its evidence [Φ(β) − Φ(α)]/Δ and its posterior's mean and variance, the
    truncated normal's moments: m = z + s·(φ(α) − φ(β))/Z, P = s²·[1 + (α·φ(α) − β·φ(β))/Z − ((φ(α) − φ(β))/Z)²],
    α = (lo − z)/s, β = (hi − z)/s, Z = Φ(β) − Φ(α), s = √R. A range narrower than ``_NARROW_RAD``: N(z; lo, R),
    posterior the point lo."""
    s = np.sqrt(meas_var)
    width = hi - lo
    narrow = width < _NARROW_RAD
    alpha = (lo - z) / s
    beta = np.where(narrow, alpha + 1.0, (hi - z) / s)  # placeholder width for point ranges (replaced below)
    log_z = _log_mass(alpha, beta)
    log_pdf_a = -0.5 * alpha**2 - 0.5 * math.log(2 * math.pi)
    log_pdf_b = -0.5 * beta**2 - 0.5 * math.log(2 * math.pi)
    ra, rb = np.exp(log_pdf_a - log_z), np.exp(log_pdf_b - log_z)  # φ(α)/Z, φ(β)/Z
    shift = ra - rb
    mean = np.clip(z + s * shift, lo, hi)
    var = meas_var * (1.0 + alpha * ra - beta * rb - shift**2)
    var = np.clip(var, _MIN_VAR, np.maximum(np.minimum(meas_var, width**2 / 4.0), _MIN_VAR))
    with np.errstate(divide="ignore"):
        log_ev = np.where(narrow, log_normal(z, lo, meas_var), log_z - np.log(np.where(narrow, 1.0, width)))
    return log_ev, np.where(narrow, lo, mean), np.where(narrow, _MIN_VAR, var)


def log_evidence(z: npt.ArrayLike, meas_var: npt.ArrayLike, lo: npt.ArrayLike, hi: npt.ArrayLike,
                 prior: DoorPrior) -> FloatArray:
    """log p(z) of an angle measurement z ~ N(a, R) under the mixture prior (module docstring); broadcasts.

    Args:
        z: measured angles (rad, relative to closed_yaw). meas_var: R (rad²).
        lo, hi: the doors' opening ranges (rad). prior: p_c and σ_c².
    """
    return evidence_and_posterior(z, meas_var, lo, hi, prior)[0]


def posterior(z: npt.ArrayLike, meas_var: npt.ArrayLike, lo: npt.ArrayLike, hi: npt.ArrayLike,
              prior: DoorPrior) -> tuple[FloatArray, FloatArray]:
    """The posterior of the door angle after z ~ N(a, R) under the mixture prior, moment-matched into one
    Gaussian: mean = Σ w_j·m_j, var = Σ w_j·(P_j + m_j²) − mean², w_j each component's share of p(z)."""
    _, mean, var = evidence_and_posterior(z, meas_var, lo, hi, prior)
    return mean, var


def evidence_and_posterior(z_in: npt.ArrayLike, r_in: npt.ArrayLike, lo_in: npt.ArrayLike, hi_in: npt.ArrayLike,
                           prior: DoorPrior) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`log_evidence` and :func:`posterior` at once: (log p(z), mean, var)."""
    z, r, lo, hi = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (z_in, r_in, lo_in, hi_in)))
    log_open, m_open, p_open = _open_component(z, r, lo, hi)
    pc = prior.closed_prob
    if pc <= 0.0:
        return log_open, m_open, p_open
    log_closed = log_normal(z, 0.0, prior.closed_var + r)
    with np.errstate(divide="ignore"):
        terms = np.stack([math.log(pc) + log_closed, math.log1p(-pc) + log_open]) if pc < 1.0 else \
            np.stack([log_closed, np.full_like(log_closed, -np.inf)])
    log_ev = np.logaddexp(terms[0], terms[1])
    w_closed = np.exp(terms[0] - log_ev)
    gain = prior.closed_var / (prior.closed_var + r)
    m_closed, p_closed = gain * z, np.maximum(gain * r, _MIN_VAR)
    mean = w_closed * m_closed + (1.0 - w_closed) * m_open
    second = w_closed * (p_closed + m_closed**2) + (1.0 - w_closed) * (p_open + m_open**2)
    return log_ev, mean, np.maximum(second - mean**2, _MIN_VAR)
