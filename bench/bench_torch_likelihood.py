"""Would a torch backend beat NumPy on the localizers' hot loop? The likelihood-field endpoint model over
particles × beams (transform every beam end point by every particle, look the distance up in the field, AMCL's
Gaussian plus z_rand, summed logs), NumPy's fused chunked path against the same computation in torch.

Issue #5 asks for a torch backend behind the same interface *if* it beats NumPy. On a CPU it does not (see
docs/benchmarks.md), so there is none; this script is the measurement, and it runs on a GPU as it is (``--device
cuda``) when one is lent.

Usage::

    OMP_NUM_THREADS=1 taskset -c 0 python bench/bench_torch_likelihood.py [--device cpu|cuda] [--map MAP.yaml]
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.io.map_server import read_map
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    DistanceField,
    build_distance_field,
    field_log_likelihood,
)

REPO = Path(__file__).resolve().parents[1]


def torch_log_likelihood(field: DistanceField, pose: np.ndarray, points: np.ndarray, z_hit: float, z_rand: float,
                         sigma_hit: float, max_range: float, device: str) -> Callable[[], np.ndarray]:
    """A closure computing Σ_b log(z_hit·exp(−d²/2σ²) + z_rand/max_range) per particle in torch, the map and the
    particles already on ``device`` (a backend would keep them there between updates)."""
    import torch

    padded = torch.from_numpy(field.padded.copy()).to(device).reshape(-1)
    width, height = field.width + 2, field.height + 2
    grid = torch.from_numpy(field.to_grid(pose)).to(device)
    cells = torch.from_numpy(points.astype(np.float64) / field.resolution_m).to(device)

    def run() -> np.ndarray:
        c, s = torch.cos(grid[:, 2:3]), torch.sin(grid[:, 2:3])
        bx, by = cells[None, :, 0], cells[None, :, 1]
        col = (grid[:, 0:1] + c * bx - s * by + 1.0).float().clamp_(0.0, width - 1.0)
        row = (grid[:, 1:2] + s * bx + c * by + 1.0).float().clamp_(0.0, height - 1.0)
        d = padded[row.long() * width + col.long()]
        pz = torch.exp(d * d * (-0.5 / sigma_hit**2)) * z_hit + z_rand / max_range
        out = torch.log(pz).sum(dim=1)
        return out.cpu().numpy()

    return run


def best_of(f: Callable[[], object], repeats: int = 7) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--map", type=Path, default=REPO / "datasets" / "sample" / "logs" / "loc_closed.map_static.yaml")
    args = ap.parse_args()
    import torch

    if args.device == "cpu":
        torch.set_num_threads(1)
    lc = load_config().localize
    field = build_distance_field(read_map(args.map), lc.laser_likelihood_max_dist)
    rng = np.random.default_rng(0)
    angles = np.linspace(-2.3, 2.3, 60)
    ranges = rng.uniform(0.5, 8.0, 60)
    points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)]).astype(np.float32)
    print(f"torch {torch.__version__} on {args.device}; 60 beams; best of 7")
    for n in (10_000, 50_000):
        pose = np.column_stack([rng.uniform(0, 40, n), rng.uniform(-1, 1, n), rng.uniform(-np.pi, np.pi, n)])
        numpy_run = partial(field_log_likelihood, field, pose, points, lc.z_hit, lc.z_rand, lc.sigma_hit, 20.0,
                            BeamCombination.PRODUCT)
        torch_run = torch_log_likelihood(field, pose, points, lc.z_hit, lc.z_rand, lc.sigma_hit, 20.0, args.device)
        agree = float(np.median(np.abs(numpy_run() - torch_run())))
        for name, f in (("numpy", numpy_run), (f"torch/{args.device}", torch_run)):
            t = best_of(f)
            print(f"N = {n:6d}  {name:10s} {t * 1e3:7.1f} ms  {n * 60 / t / 1e6:6.1f} M particle-beams/s")
        print(f"           median |numpy − torch| per particle: {agree:.2e} nats")


if __name__ == "__main__":
    main()
