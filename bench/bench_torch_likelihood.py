"""Does the torch backend (``localize.backend: torch``) beat NumPy on the localizers' hot loop? The likelihood
field over particles × beams, through the one interface both backends share: ``endpoint_distances`` ((N, B)
distances back in host memory, what beam skipping and the RBPF's door terms consume) and ``field_log_likelihood``
(fused: only (N,) log-likelihoods come back). Particles spread over the sample's corridor, 60 beams. A field built
with ``torch_device`` runs in torch (pipeline/localize/torch_field.py); the same poses go through both.

Usage::

    OMP_NUM_THREADS=1 taskset -c 0 python bench/bench_torch_likelihood.py [--device cpu|cuda] [--map MAP.yaml]
"""

from __future__ import annotations

import argparse
import platform
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.io.map_server import read_map
from doorbatch.pipeline.localize.likelihood_field import (
    BeamCombination,
    build_distance_field,
    endpoint_distances,
    field_log_likelihood,
)

REPO = Path(__file__).resolve().parents[1]


def best_of(f: Callable[[], object], repeats: int = 7) -> float:
    """Best wall time of ``repeats`` calls after one warm-up (each call ends with its result in host memory)."""
    f()
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
    ap.add_argument("--particles", type=int, nargs="+", default=[1_000, 10_000, 50_000, 200_000])
    args = ap.parse_args()
    import torch

    if args.device == "cpu":
        torch.set_num_threads(1)
    name = torch.cuda.get_device_name() if args.device.startswith("cuda") else platform.processor()
    lc = load_config().localize
    occ = read_map(args.map)
    numpy_field = build_distance_field(occ, lc.laser_likelihood_max_dist)
    torch_field = build_distance_field(occ, lc.laser_likelihood_max_dist, torch_device=args.device)
    rng = np.random.default_rng(0)
    angles = np.linspace(-2.3, 2.3, 60)
    ranges = rng.uniform(0.5, 8.0, 60)
    points = np.column_stack([ranges * np.cos(angles), ranges * np.sin(angles)]).astype(np.float32)
    print(f"{time.strftime('%Y-%m-%d %H:%M')} torch {torch.__version__} on {args.device} ({name}); NumPy "
          f"{np.__version__}; 60 beams; best of 7")
    print("| particles | call | NumPy ms | torch ms | NumPy M/s | torch M/s | cells equal |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for n in args.particles:
        pose = np.column_stack([rng.uniform(0, 40, n), rng.uniform(-1, 1, n), rng.uniform(-np.pi, np.pi, n)])
        equal = float(np.mean(endpoint_distances(numpy_field, pose, points)
                              == endpoint_distances(torch_field, pose, points)))
        for call in ("endpoint_distances", "field_log_likelihood"):
            if call == "endpoint_distances":
                runs = [partial(endpoint_distances, f, pose, points) for f in (numpy_field, torch_field)]
            else:
                runs = [partial(field_log_likelihood, f, pose, points, lc.z_hit, lc.z_rand, lc.sigma_hit, 20.0,
                                BeamCombination.PRODUCT) for f in (numpy_field, torch_field)]
            t_np, t_torch = best_of(runs[0]), best_of(runs[1])
            print(f"| {n:,} | {call} | {t_np * 1e3:.2f} | {t_torch * 1e3:.2f} | {n * 60 / t_np / 1e6:.0f} | "
                  f"{n * 60 / t_torch / 1e6:.0f} | {equal:.6f} |")


if __name__ == "__main__":
    main()
