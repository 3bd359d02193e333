"""EM stage speed (paper 001): the whole em stage (structure search + EM) on the sample site's three
mapping passes, and the time of one EM iteration (E-step + M-step) as the number of scans grows.

Run: ``taskset -c 0 python bench/bench_em.py [--strides 8,4,2,1]``. Reading the logs and the poses is
not timed. Figures are CPU time of the process (the machine is shared; CPU time leaves out the waits).
Row 1 is the stage with the default config (every 2nd scan, every 2nd beam; then walls proposed and re-cut
over every scan and beam), and beside it the stage without that final step; the other rows time
``run_em`` iterations on the stage's final map with the scan stride varied (beam stride 2).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from doorbatch.config import DoorbatchConfig
from doorbatch.io.recording import load_recording
from doorbatch.pipeline.mapping import pass_poses
from doorbatch.pipeline.objectmap.em import EmTrace, run_em
from doorbatch.pipeline.objectmap.stage import build_object_map, collect_beams, final_step_beams

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--strides", default="8,4,2,1", help="scan strides for the per-iteration rows")
    args = ap.parse_args()
    config = DoorbatchConfig()
    logs = sorted((ROOT / "datasets" / "sample" / "logs").glob("map_pass*.mcap"))
    recs = [load_recording(p, config, with_colors=True) for p in logs]
    passes = [pass_poses(r, "reference", config) for r in recs]
    beams = collect_beams(recs, passes, config.em)
    final_beams = final_step_beams(recs, passes, config.em)
    c0 = time.process_time()
    searched = build_object_map(beams, config.em)  # no final step: the search alone
    search_s = time.process_time() - c0
    c0 = time.process_time()
    result = build_object_map(beams, config.em, final=final_beams)
    stage_s = time.process_time() - c0
    n_final = len(final_beams.beams) if final_beams is not None else 0
    print(f"em stage, sample mapping passes ({len(logs)} passes, {result.n_beams} beams; {n_final} in the "
          f"final wall step): {stage_s:.1f} s CPU; {len(result.object_map.walls)} walls, {len(result.doors)} doors, "
          f"{len(result.trace.seconds)} EM iterations; without the final wall step {search_s:.1f} s, "
          f"{len(searched.object_map.walls)} walls")
    print("| scans | beams | s per EM iteration (CPU) |")
    print("| --- | --- | --- |")
    for stride in (int(s) for s in args.strides.split(",")):
        em = config.em.model_copy(update={"scan_stride": stride, "beam_stride": 2})
        b = collect_beams(recs, passes, em)
        n_scans = sum(len(range(0, len(r.scans), stride)) for r in recs)
        trace = EmTrace()
        c0 = time.process_time()
        run_em(b, result.object_map, em, iterations=3, trace=trace, tolerance=0.0)
        per_iter = (time.process_time() - c0) / max(len(trace.seconds), 1)
        print(f"| {n_scans} | {len(b)} | {per_iter:.2f} |")


if __name__ == "__main__":
    main()
