"""Veiling (mixed pixels): a beam that straddles an edge returns a range between the two surfaces it partly hit.

Such points float in the air behind door edges, jambs and wall corners, where the door search looks: in an outside
user's laser they filled doorways with occupied cells and hid two of four doors. The test is ROS laser_filters'
ScanShadowsFilter (the filter most ROS robots run on their scans). For end points P_i and P_j of beams i and j
(|i − j| ≤ ``window``, θ = |i − j| · Δα apart), the angle at P_i between the ray back to the laser and P_i → P_j is

    β = atan2(r_j sin θ, r_i − r_j cos θ),

the incidence of the surface through both points. A point with β < β_min or β > π − β_min against a neighbour lies
along its neighbour's beam, not across it: a veiling point, or the last point of a surface seen at a grazing angle
under β_min (its neighbours on that surface are as far along the beam as across it: few metres' worth of hits, and
the noisiest). Both ends of a depth jump go too, one beam each (laser_filters drops the farther one, and the nearer
with ``remove_shadow_start_point``): a leaf's free end loses a beam. Only measured points take part: a beam outside
[range_min, range_max) (no return, a driver's error code) is neither marked nor makes a neighbour marked.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

BoolArray = npt.NDArray[np.bool_]


def veiling_mask(ranges: npt.ArrayLike, angle_increment_rad: float, min_angle_rad: float, window: int = 1,
                 range_min_m: float = 0.0, range_max_m: float = np.inf) -> BoolArray:
    """True for the beams of one scan whose end point is a veiling point (module docstring). Beams without a measured
    range (not finite, or outside [``range_min_m``, ``range_max_m``)) are never marked and never make a neighbour
    marked."""
    r = np.asarray(ranges, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        measured = np.isfinite(r) & (r > 0.0) & (r >= range_min_m) & (r < range_max_m)
    out = np.zeros(r.shape[0], dtype=bool)
    tan_min = np.tan(min_angle_rad)
    for k in range(1, window + 1):
        theta = k * abs(angle_increment_rad)
        a, b = r[:-k], r[k:]
        both = measured[:-k] & measured[k:]
        for near, far, at in ((a, b, slice(None, -k)), (b, a, slice(k, None))):  # P_i = near, P_j = far
            with np.errstate(invalid="ignore"):  # inf − inf where neither returned: not ``both``
                y = far * np.sin(theta)
                x = near - far * np.cos(theta)
                shadow = both & (np.abs(y) < tan_min * np.abs(x))  # β < β_min (x > 0) or β > π − β_min (x < 0)
            out[at] |= shadow
    return out
