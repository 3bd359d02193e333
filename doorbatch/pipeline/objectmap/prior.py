"""The map prior of paper 001 Sec. IV: p(M) ∝ exp(−ρG·MG − ρS·MS − ρD·MD − ρL·L[M])."""

from __future__ import annotations

from doorbatch.config import ObjectMapConfig
from doorbatch.pipeline.objectmap.model import ObjectMap


def parameter_counts(obj_map: ObjectMap, per_door_width: bool) -> tuple[int, int, int]:
    """(MG, MS, MD): global parameters (door width; 3 means + 3 variances per class colour), static local
    ones (2 per wall line + 2 per segment; 2 per hinge, + 1 with per-door widths) and dynamic ones (one
    angle per door per pass)."""
    n_doors = len(obj_map.doors)
    color = 6 if obj_map.classes.has_color else 0
    mg = (color if obj_map.walls else 0) + ((color + (0 if per_door_width else 1)) if n_doors else 0)
    ms = sum(2 + 2 * w.segments.shape[0] for w in obj_map.walls) + n_doors * (3 if per_door_width else 2)
    md = n_doors * obj_map.n_passes
    return mg, ms, md


def log_prior(obj_map: ObjectMap, config: ObjectMapConfig) -> float:
    """log p(M) up to a constant."""
    mg, ms, md = parameter_counts(obj_map, config.per_door_width)
    return -(config.rho_global * mg + config.rho_static * ms + config.rho_dynamic * md
             + config.rho_length_per_m * obj_map.total_length())
