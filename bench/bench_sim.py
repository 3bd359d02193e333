"""Simulator throughput: ray casting (720 beams × 50 segments) and full laser scans, on one core.

Run: ``python bench/bench_sim.py`` (add ``--seconds N`` for longer runs). Prints scans per second for

1. ``cast_rays`` alone, 720 beams × 50 random segments in a 20 m box (with reused buffers, as the
   simulator calls it, and with fresh allocations);
2. ``simulate_scan``: a full laser scan in the office corridor world (static segments + door leaves in
   one cast, two people as circles, range noise, dropouts), plus per-beam colors;
3. the whole default scenario written to an MCAP file (simulated seconds per wall second).

Single-threaded: BLAS threads are pinned to 1 before NumPy is imported.
"""

from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from doorbatch.sim.raycast import RayBuffers, cast_rays  # noqa: E402
from doorbatch.sim.scenario import load_scenario  # noqa: E402
from doorbatch.sim.sensors import beam_colors, laser_model, make_scene, simulate_scan  # noqa: E402
from doorbatch.sim.simulate import random_streams, run_simulation  # noqa: E402
from doorbatch.sim.timeline import plan_scenario  # noqa: E402
from doorbatch.sim.world import load_world  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def rate(fn: Callable[[], object], seconds: float) -> float:
    """Calls per second of ``fn`` (best of three timed runs of about ``seconds`` / 3 each)."""
    for _ in range(20):
        fn()
    best = 0.0
    for _ in range(3):
        n, start = 0, time.perf_counter()
        while (elapsed := time.perf_counter() - start) < seconds / 3:
            fn()
            n += 1
        best = max(best, n / elapsed)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="time per measurement")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    segments = rng.uniform(-10.0, 10.0, (50, 2, 2))
    angles = np.linspace(-0.75 * np.pi, 0.75 * np.pi, 720)
    directions = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    origin = np.array([0.3, -0.2])
    buffers = RayBuffers()
    cast_buf = rate(lambda: cast_rays(origin, directions, segments, buffers), args.seconds)
    cast_fresh = rate(lambda: cast_rays(origin, directions, segments), args.seconds)

    world = load_world(REPO / "configs" / "worlds" / "office_corridor.yaml")
    scenario = load_scenario("default")
    streams = random_streams(0)
    plan = plan_scenario(world, scenario, streams["scenario"])
    laser = laser_model(scenario.sensors.laser)
    scene = make_scene(world, plan.doors.angles_at([10.0])[0], plan.people, plan.people.positions_at([10.0])[0])
    pose = np.array([9.0, 0.1, 0.05])
    n_surfaces = scene.n_static + scene.n_doors
    scan = rate(lambda: simulate_scan(pose, scene, laser, streams["laser"], buffers), args.seconds)
    sample = simulate_scan(pose, scene, laser, streams["laser"], buffers)
    colors = rate(lambda: beam_colors(sample, scene, laser, scenario.sensors.colors, streams["colors"]), args.seconds)

    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        summary = run_simulation(REPO / "configs" / "worlds" / "office_corridor.yaml", Path(tmp) / "bench.mcap",
                                 "default", 0, "mcap")
        wall = time.perf_counter() - start
        size_mb = summary.log_path.stat().st_size / 1e6

    print(f"machine: {platform.processor() or platform.machine()}, numpy {np.__version__}, 1 thread")
    print(f"cast_rays 720 beams x 50 segments (reused buffers): {cast_buf:8.0f} scans/s")
    print(f"cast_rays 720 beams x 50 segments (fresh arrays):   {cast_fresh:8.0f} scans/s")
    print(f"simulate_scan office corridor, 720 beams x {n_surfaces} segments + {scene.people_xy.shape[0]} people, "
          f"noise: {scan:8.0f} scans/s")
    print(f"beam_colors 720 beams: {colors:8.0f} scans/s; laser + colors: {1 / (1 / scan + 1 / colors):8.0f} scans/s")
    print(f"default scenario, all sensors, to MCAP: {summary.duration_s:.1f} s simulated in {wall:.1f} s "
          f"({summary.duration_s / wall:.1f}x real time, {sum(summary.message_counts.values())} messages, "
          f"{size_mb:.1f} MB)")


if __name__ == "__main__":
    main()
