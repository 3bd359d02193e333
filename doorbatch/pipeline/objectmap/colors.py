"""Class colours: the ML Gaussians of paper 001 Sec. V, and the colour-only baseline of Sec. VII (a
mixture of two Gaussians fitted to all beam colours, no shape or motion)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.objectmap.model import DOOR, WALL, ClassParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def _gaussian_loglik(color: FloatArray, mean: FloatArray, var: FloatArray) -> FloatArray:
    """log N(l; µ, diag σ²) for colours (N, 3) under one (3,) or per-row (N, 3) Gaussian."""
    return np.asarray(-0.5 * np.sum((color - mean) ** 2 / var + np.log(2.0 * np.pi * var), axis=-1),
                      dtype=np.float64)


def _component_logliks(color: FloatArray, weights: FloatArray, means: FloatArray, variances: FloatArray
                       ) -> FloatArray:
    """(N, M): log π_m + log N(l; µ_m, diag σ_m²) for colours (N, 3) and M weighted diagonal Gaussians."""
    return np.stack([np.log(w) + _gaussian_loglik(color, m, v)
                     for w, m, v in zip(weights, means, variances, strict=True)], 1)


def class_color_loglik(color: FloatArray, c: int, classes: ClassParams) -> FloatArray:
    """log p(l | class c) for colours (N, 3): the class Gaussian, or for doors with a mixture per paint
    log [s·N(l; µ_door, σ_door²) + (1 − s)·Σ_m π_m N(l; µ_m, σ_m²)] with s = 1/(M + 1)."""
    if c == DOOR and classes.door_mix_weight.size:
        # the paper's one Gaussian over all door colours stays as one more component, of an equal share 1/(M+1):
        # a paint no component has learned yet (a door class fitted to the doors adopted first) is still
        # scored as paper 001 scores it, not as an outlier of the learned paints
        share = 1.0 / (classes.door_mix_weight.size + 1)
        ll = _component_logliks(color, np.concatenate([[share], (1.0 - share) * classes.door_mix_weight]),
                                np.concatenate([classes.color_mean[DOOR][None], classes.door_mix_mean]),
                                np.concatenate([classes.color_var[DOOR][None], classes.door_mix_var]))
        return np.asarray(np.logaddexp.reduce(ll, axis=1), dtype=np.float64)
    return _gaussian_loglik(color, classes.color_mean[c], classes.color_var[c])


def weighted_mixture(color: FloatArray, w: FloatArray, init_mean: FloatArray, var_floor: float,
                     iterations: int = 30) -> tuple[FloatArray, FloatArray, FloatArray]:
    """EM for a mixture of M diagonal Gaussians on colours (N, 3) with beam weights w, started at the
    (M, 3) means ``init_mean``: (weights (M,), means, variances). A component left without weight is
    dropped."""
    mean = init_mean.astype(np.float64).copy()
    var = np.tile(np.maximum(np.average((color - np.average(color, axis=0, weights=w)) ** 2, axis=0, weights=w),
                             var_floor), (mean.shape[0], 1))
    pi = np.full(mean.shape[0], 1.0 / mean.shape[0])
    for _ in range(iterations):
        ll = _component_logliks(color, pi, mean, var)
        resp = np.exp(ll - np.logaddexp.reduce(ll, axis=1, keepdims=True)) * w[:, None]
        nk = resp.sum(axis=0)
        keep = nk > 1.0
        resp, nk = resp[:, keep], nk[keep]
        pi = nk / nk.sum()
        mean = (resp.T @ color) / nk[:, None]
        var = np.maximum(np.stack([resp[:, k] @ (color - mean[k]) ** 2 for k in range(nk.size)]) / nk[:, None],
                         var_floor)
    return pi, mean, var


def _spread_means(color: FloatArray, w: FloatArray, m: int) -> FloatArray:
    """m starting means: the weighted mean, then repeatedly the colour farthest from those chosen
    (deterministic farthest-point seeding)."""
    chosen = [np.average(color, axis=0, weights=w)]
    for _ in range(m - 1):
        d = np.min(np.stack([np.sum((color - c) ** 2, axis=1) for c in chosen]), axis=0)
        chosen.append(color[int(np.argmax(np.where(w > 0.5, d, -1.0)))])
    return np.array(chosen)


def ml_class_colors(classes: ClassParams, color: FloatArray, cls: IntArray, e: FloatArray, var_floor: float,
                    door_components: int = 1) -> ClassParams:
    """µ_C = Σ e·l / Σ e over the beams whose first object is of class C (and that have a colour); the
    per-channel variance likewise, floored at ``var_floor``. A class without weight keeps its values.
    ``door_components`` > 1: the door colours also as a mixture of that many Gaussians (a door class per
    paint), started from the last mixture when it has that many components."""
    mean, var = classes.color_mean.copy(), classes.color_var.copy()
    ok = np.isfinite(color[:, 0])
    mix = (classes.door_mix_weight, classes.door_mix_mean, classes.door_mix_var)
    for c in (WALL, DOOR):
        sel = ok & (cls == c)
        w = e[sel]
        if w.sum() < 1.0:
            continue
        mean[c] = w @ color[sel] / w.sum()
        var[c] = np.maximum(w @ (color[sel] - mean[c]) ** 2 / w.sum(), var_floor)
        if c == DOOR and door_components > 1:
            start = (classes.door_mix_mean if classes.door_mix_mean.shape[0] == door_components
                     else _spread_means(color[sel], w, door_components))
            mix = weighted_mixture(color[sel], w, start, var_floor)
    return replace(classes, color_mean=mean, color_var=var, has_color=True, door_mix_weight=mix[0],
                   door_mix_mean=mix[1], door_mix_var=mix[2])


@dataclass(frozen=True)
class ColorMixture:
    """Two diagonal Gaussians on RGB and each colour's component."""

    weights: FloatArray  # (2,)
    mean: FloatArray  # (2, 3)
    var: FloatArray  # (2, 3)
    labels: IntArray  # (N,)


def two_gaussian_mixture(color: FloatArray, iterations: int = 100, var_floor: float = 4.0, seed: int = 0
                         ) -> ColorMixture:
    """EM for a mixture of two diagonal Gaussians on (N, 3) colours (the paper's colour-only model), started
    at two colours drawn at random (:func:`weighted_mixture` with unit weights); labels: the likelier one."""
    init = color[np.random.default_rng(seed).choice(color.shape[0], 2, replace=False)]
    weights, mean, var = weighted_mixture(color, np.ones(color.shape[0]), init, var_floor, iterations)
    labels = np.argmax(_component_logliks(color, weights, mean, var), axis=1)
    return ColorMixture(weights, mean, var, labels.astype(np.int64))
