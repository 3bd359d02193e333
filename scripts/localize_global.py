"""Global localization success rates of MCL and the RBPF (issue #5): particles uniform over the map's free space.

A run succeeds when the filter converges (weighted position std ≤ converged_xy_std_m and yaw std ≤
converged_yaw_std_deg) within 30 s of the first scan, and the estimate is then within 0.3 m and 10° of the
reference, both at convergence and at the end of the log. Particles: ``localize.global_particles`` = N and
``localize.max_particles`` = N (KLD may keep fewer once the cloud has gathered).

Usage::

    python scripts/localize_global.py --map /tmp/lm/map [--logs datasets/sample/logs] [--cases closed partial] \
        [--particles 1000 2000 5000 10000 20000 50000] [--seeds 0 1 ... 9] [--plot out.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from doorbatch.config import load_config
from doorbatch.geometry.rotations import wrap_angle
from doorbatch.geometry.se2 import interpolate_poses
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.localize.run import load_localization_map, localize, truth_localization_map

WINDOW_S = 30.0
MAX_XY_M = 0.3
MAX_YAW_DEG = 10.0


def success(log: Path, map_dir: Path | None, method: str, n: int, seed: int, overrides: list[str]) -> bool:
    config = load_config(overrides=[*overrides, f"seed={seed}", f"localize.global_particles={n}",
                                    f"localize.max_particles={n}"])
    lmap = (truth_localization_map(log.with_suffix(".truth.yaml"), config.localize) if map_dir is None
            else load_localization_map(map_dir, config.localize))
    result = localize(log, lmap, config, method, "global")
    if result.converged_ns is None or (result.converged_ns - int(result.stamps_ns[0])) / 1e9 > WINDOW_S:
        return False
    rec = load_recording(log, config)
    assert rec.reference is not None
    at = int(np.searchsorted(result.stamps_ns, result.converged_ns))
    idx = np.array([at, len(result) - 1])
    ref, ok = interpolate_poses(rec.reference.stamps_ns, rec.reference.poses, result.stamps_ns[idx])
    xy = np.hypot(*(result.pose[idx, :2] - ref[:, :2]).T)
    yaw = np.degrees(np.abs(wrap_angle(result.pose[idx, 2] - ref[:, 2])))
    return bool(ok.all() and np.all(xy <= MAX_XY_M) and np.all(yaw <= MAX_YAW_DEG))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=Path, default=None)
    ap.add_argument("--logs", type=Path, default=Path("datasets/sample/logs"))
    ap.add_argument("--cases", nargs="+", default=["closed", "partial"])
    ap.add_argument("--methods", nargs="+", default=["mcl", "rbpf"])
    ap.add_argument("--particles", nargs="+", type=int, default=[1000, 2000, 5000, 10000, 20000, 50000])
    ap.add_argument("--seeds", nargs="+", type=int, default=list(range(10)))
    ap.add_argument("--truth-map", action="store_true",
                    help="instead of --map, each log's truth: static map and all doors (<log>.truth.yaml)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], help="config override key=value")
    ap.add_argument("--plot", type=Path, default=None, help="PNG of success rate against particles")
    args = ap.parse_args()
    if (args.map is None) == (not args.truth_map):
        ap.error("give exactly one of --map and --truth-map")
    map_dir = None if args.truth_map else args.map
    rates: dict[tuple[str, str], list[float]] = {}
    for case in args.cases:
        log = args.logs / f"loc_{case}.mcap"
        for method in args.methods:
            rates[(case, method)] = [
                float(np.mean([success(log, map_dir, method, n, s, args.overrides) for s in args.seeds]))
                for n in args.particles]
    print(f"success rate over seeds {args.seeds} (≤ {MAX_XY_M} m, ≤ {MAX_YAW_DEG:.0f}°, converged ≤ {WINDOW_S:.0f} s)")
    print("| doors | method | " + " | ".join(f"{n:,}" for n in args.particles) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in args.particles) + " |")
    for (case, method), r in rates.items():
        print(f"| {case} | {method} | " + " | ".join(f"{100 * v:.0f} %" for v in r) + " |")
    if args.plot is not None:
        try:
            import matplotlib
        except ImportError:
            print("no matplotlib: no plot (pip install matplotlib)")
            return

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for (case, method), r in rates.items():
            ax.semilogx(args.particles, [100 * v for v in r], marker="o", label=f"{method}, doors {case}",
                        linestyle="-" if method == "rbpf" else "--")
        ax.set_xlabel("particles")
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-5, 105)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(args.plot, dpi=100)
        print(f"plot: {args.plot}")


if __name__ == "__main__":
    main()
