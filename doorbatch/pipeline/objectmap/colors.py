"""Class colours: the ML Gaussians of paper 001 Sec. V, and the colour-only baseline of Sec. VII (a
mixture of two Gaussians fitted to all beam colours, no shape or motion)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from doorbatch.pipeline.objectmap.model import ClassParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def ml_class_colors(classes: ClassParams, color: FloatArray, cls: IntArray, e: FloatArray, var_floor: float
                    ) -> ClassParams:
    """µ_C = Σ e·l / Σ e over the beams whose first object is of class C (and that have a colour); the
    per-channel variance likewise, floored at ``var_floor``. A class without weight keeps its values."""
    mean, var = classes.color_mean.copy(), classes.color_var.copy()
    ok = np.isfinite(color[:, 0])
    for c in (0, 1):
        sel = ok & (cls == c)
        w = e[sel]
        if w.sum() < 1.0:
            continue
        mean[c] = w @ color[sel] / w.sum()
        var[c] = np.maximum(w @ (color[sel] - mean[c]) ** 2 / w.sum(), var_floor)
    return replace(classes, color_mean=mean, color_var=var, has_color=True)


@dataclass(frozen=True)
class ColorMixture:
    """Two diagonal Gaussians on RGB and each colour's component."""

    weights: FloatArray  # (2,)
    mean: FloatArray  # (2, 3)
    var: FloatArray  # (2, 3)
    labels: IntArray  # (N,)


def two_gaussian_mixture(color: FloatArray, iterations: int = 100, var_floor: float = 4.0, seed: int = 0
                         ) -> ColorMixture:
    """EM for a mixture of two diagonal Gaussians on (N, 3) colours (the paper's colour-only model)."""
    rng = np.random.default_rng(seed)
    n = color.shape[0]
    mean = color[rng.choice(n, 2, replace=False)].astype(np.float64)
    var = np.tile(np.maximum(color.var(axis=0), var_floor), (2, 1))
    weights = np.array([0.5, 0.5])
    resp = np.zeros((n, 2))
    for _ in range(iterations):
        ll = np.stack([np.log(weights[c]) - 0.5 * np.sum((color - mean[c]) ** 2 / var[c]
                                                          + np.log(2 * np.pi * var[c]), axis=1) for c in (0, 1)], 1)
        resp = np.exp(ll - np.logaddexp(ll[:, :1], ll[:, 1:]))
        nk = resp.sum(axis=0) + 1e-9
        weights = nk / n
        mean = (resp.T @ color) / nk[:, None]
        var = np.maximum(np.stack([resp[:, c] @ (color - mean[c]) ** 2 for c in (0, 1)]) / nk[:, None], var_floor)
    return ColorMixture(weights, mean, var, np.argmax(resp, axis=1).astype(np.int64))
