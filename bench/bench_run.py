"""``doorbatch run`` on the bundled sample: the first run, an unchanged rerun, and a rerun after one
localization log changed.

Run: ``python bench/bench_run.py [--dataset datasets/sample] [--workers N]``. Each invocation is the CLI in a
fresh process (``python -m doorbatch.cli run``), so interpreter start and imports count, as for a user or
cron. The dataset is copied to a temporary folder first (the changed-log run rewrites one log there: the
first 40 s of ``loc_open``, cut with ``doorbatch.io.split.copy_window``). Prints wall seconds per run, the
steps each run did, and the rerun's share of the first run (acceptance: ≤ 5 %).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from doorbatch.io.split import copy_window

REPO = Path(__file__).resolve().parents[1]


def timed_run(dataset: Path, out: Path, workers: int) -> tuple[float, dict[str, object]]:
    """Wall seconds and the JSON summary of one ``doorbatch run`` in a fresh process."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmd = [sys.executable, "-m", "doorbatch.cli", "run", str(dataset), "-o", str(out), "--workers", str(workers),
           "--json"]
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    if done.returncode != 0:
        raise SystemExit(f"doorbatch run failed ({done.returncode}): {done.stderr.strip()}")
    return seconds, json.loads(done.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--dataset", type=Path, default=REPO / "datasets" / "sample")
    parser.add_argument("--workers", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        dataset = Path(shutil.copytree(args.dataset, Path(tmp) / args.dataset.name))
        out = Path(tmp) / "out"
        first, s1 = timed_run(dataset, out, args.workers)
        print(f"first run:        {first:7.2f} s  done {s1['done']}, up to date {s1['up_to_date']}")
        second, s2 = timed_run(dataset, out, args.workers)
        print(f"unchanged rerun:  {second:7.2f} s  done {s2['done']}, up to date {s2['up_to_date']}  "
              f"({100 * second / first:.1f} % of the first)")
        log = dataset / "logs" / "loc_open.mcap"
        if log.exists():
            t0 = 1_700_000_000_000_000_000
            copy_window(args.dataset / "logs" / "loc_open.mcap", log, t0, t0 + 40_000_000_000)
            third, s3 = timed_run(dataset, out, args.workers)
            redone = [o["step"] for o in s3["outcomes"] if o["status"] == "done"]  # type: ignore[attr-defined]
            print(f"one log changed:  {third:7.2f} s  done {s3['done']} ({', '.join(redone)}), "
                  f"up to date {s3['up_to_date']}")


if __name__ == "__main__":
    main()
