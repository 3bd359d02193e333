"""The sample logs as a robot without ROS logs them (Foxglove SDK, protobuf), against the ROS originals.

Each log is rewritten with the test's writer (``tests/io/test_foxglove.py``: the mounts once on /tf, odometry as
foxglove.Odometry, the reference as foxglove.PoseInFrame; colors have no Foxglove schema, so the em stage does not
run and both maps are the grid stage's). Then ``doorbatch map`` on both sets of mapping passes (map.pgm and
doors.parquet compared), and ``doorbatch localize`` + ``evaluate`` of one localization log on the ROS map.

Usage: ``PYTHONPATH=. python scripts/foxglove_compare.py [--work DIR] [--log loc_partial] [--method rbpf]
[--fox-set KEY=VALUE ...] [--no-return-code M]`` (``--fox-set``: config for the Foxglove log's run only, e.g. the
range limits its schema cannot state: ``localize.laser_max_range_fallback=20``; ``--no-return-code``: the Foxglove
logs' beams without an echo written as M, as simulators that clamp at their maximum range write them, not +inf).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from doorbatch.cli import main
from doorbatch.io.reader import open_log
from tests.io.test_foxglove import as_foxglove, write_sdk

SAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "sample" / "logs"


def rewrite(log: Path, out: Path, no_return_code: float | None = None) -> Path:
    with open_log(log) as reader:
        msgs = [(r.topic, r.msgtype, r.log_time_ns, r.msg) for r in reader.raw_messages()]
    if no_return_code is not None:
        for _, msgtype, _, msg in msgs:
            if msgtype.endswith("LaserScan"):
                msg.ranges = np.where(np.isposinf(msg.ranges), no_return_code, msg.ranges).astype(np.float32)
    return write_sdk(out, as_foxglove(msgs))


def run(argv: list[str]) -> None:
    code = main(argv)
    if code != 0:
        raise SystemExit(f"doorbatch {' '.join(argv)} exited {code}")


def metrics(run_dir: Path, reference: Path, out: Path) -> dict[str, float]:
    run(["evaluate", str(run_dir), "--reference", str(reference), "-o", str(out), "-q"])
    table = pq.read_table(out / "metrics.parquet").to_pandas()
    return {r.metric: float(r.value) for r in table.itertuples() if r.metric.startswith("ape_trans_")}


def compare(work: Path, log_name: str, method: str, fox_sets: list[str], no_return_code: float | None) -> None:
    passes = sorted(SAMPLE.glob("map_pass*.mcap"))
    fox_passes = [rewrite(p, work / f"fox_{p.name}", no_return_code) for p in passes]
    for name, logs in (("ros", passes), ("fox", fox_passes)):
        run(["map", *map(str, logs), "-o", str(work / f"map_{name}"), "--stages", "grid", "-q"])
    same_pgm = (work / "map_ros" / "map.pgm").read_bytes() == (work / "map_fox" / "map.pgm").read_bytes()
    doors = [pq.read_table(work / f"map_{n}" / "doors.parquet") for n in ("ros", "fox")]
    print(f"map: map.pgm identical {same_pgm}; doors {doors[0].num_rows} / {doors[1].num_rows}, "
          f"doors.parquet identical {doors[0].equals(doors[1])}")
    ros_log = SAMPLE / f"{log_name}.mcap"
    fox_log = rewrite(ros_log, work / f"fox_{log_name}.mcap", no_return_code)
    for name, log in (("ros", ros_log), ("fox", fox_log)):
        sets = [a for kv in fox_sets for a in ("--set", kv)] if name == "fox" else []
        run(["localize", str(log), "--map", str(work / "map_ros"), "-o", str(work / f"loc_{name}"), "--method",
             method, "-q", *sets])
        m = metrics(work / f"loc_{name}", ros_log, work / f"eval_{name}")
        print(f"localize {log_name} ({method}, {name}): APE RMSE {m['ape_trans_rmse']:.4f} m, mean "
              f"{m['ape_trans_mean']:.4f} m, max {m['ape_trans_max']:.4f} m")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--log", default="loc_partial")
    parser.add_argument("--method", default="rbpf", choices=["rbpf", "mcl"])
    parser.add_argument("--fox-set", action="append", default=[], metavar="KEY=VALUE")
    parser.add_argument("--no-return-code", type=float, default=None, metavar="M")
    args = parser.parse_args()
    if args.work is None:
        with tempfile.TemporaryDirectory() as tmp:
            compare(Path(tmp), args.log, args.method, args.fox_set, args.no_return_code)
    else:
        args.work.mkdir(parents=True, exist_ok=True)
        compare(args.work, args.log, args.method, args.fox_set, args.no_return_code)
