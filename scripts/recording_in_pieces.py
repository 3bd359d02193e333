"""The sample's mapping run as a user may hold it, against the three passes it was simulated as.

- ``pieces``: the three passes as rosbag2 ``--max-bag-duration`` leaves them, ``/tf_static`` in the first only
  (each later piece borrows its mounts: :func:`~doorbatch.io.recording.load_passes`), given in the order a shell
  glob would list ``run_10`` before ``run_2`` (mapped in time order: :func:`~doorbatch.pipeline.mapping.time_order`);
- ``one log``: the three passes in one recording, as one pass and cut into passes of ``--pass-s`` seconds
  (``mapping.pass_duration_s``: :mod:`doorbatch.pipeline.time_passes`).

Each is mapped (grid stage) and scored: against the simulator's truth (doors found among those that moved, the
largest hinge and leaf-length errors) where the poses are the reference's; against the three passes' map (the
odometry's frame) where they are scan-matched or odometry; and whether ``map.pgm`` is the three passes' byte for
byte.

Usage: ``PYTHONPATH=. python scripts/recording_in_pieces.py [--work DIR] [--pass-s 47] [--pose-source scanmatch]``
(scan matching: the pieces must chain by their odometry, so the out-of-order row is refused without the time order)
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from doorbatch.cli import main
from doorbatch.config import DoorbatchConfig
from doorbatch.io.log_writer import LogWriter
from doorbatch.io.mapdir import read_door_set
from doorbatch.io.reader import open_log
from doorbatch.io.sim_truth import read_truth
from doorbatch.pipeline.evaluate.door_map import score_doors, truth_doors

SAMPLE = Path(__file__).resolve().parents[1] / "datasets" / "sample" / "logs"


def write(out: Path, logs: list[Path], keep_static: bool) -> Path:
    """``logs`` into one MCAP, their /tf_static kept only where ``keep_static``."""
    with LogWriter(out) as writer:
        for log in logs:
            with open_log(log) as reader:
                for raw in reader.raw_messages():
                    if keep_static or raw.topic != "/tf_static":
                        writer.write_raw(raw)
    return out


def mapped(logs: list[Path], out: Path, against: Path | None, *sets: str) -> str:
    """Map ``logs`` into ``out``; its doors against the truth (in the truth's frame: a reference pose source) or,
    where ``against`` is given, against that map's doors (the same odometry frame)."""
    args = [a for kv in sets for a in ("--set", kv)]
    if main(["map", *map(str, logs), "-o", str(out), "--stages", "grid", "-q", *args]) != 0:
        return "refused"
    if against is None:
        truth, moved = truth_doors(read_truth(SAMPLE / "map.truth.yaml"),
                                   math.radians(DoorbatchConfig().doors.min_opening_deg))
    else:
        truth = read_door_set(against)
        moved = [True] * len(truth)
    s = score_doors(read_door_set(out), truth, moved)
    worst = (f"hinge ≤ {s.hinge_error_m.max():.3f} m, length ≤ {abs(s.length_error_m).max():.3f} m"
             if len(s.matches) else "no match")
    whose = "the truth's moved doors" if against is None else "the three passes' doors"
    return f"{len(s.matches)} of {len(moved) if against is not None else int(sum(moved))} of {whose}, " \
           f"precision {s.precision:.2f}, {worst}"


def run(work: Path, pass_s: float, pose_source: str) -> None:
    passes = [SAMPLE / f"map_pass{k}.mcap" for k in (1, 2, 3)]
    pieces = [write(work / f"run_{k}.mcap", [p], keep_static=k == 1) for k, p in enumerate(passes, start=1)]
    one = write(work / "one.mcap", passes, keep_static=True)
    rows = [("three passes", passes, ()), ("pieces, /tf_static in the first", pieces, ()),
            ("pieces as a glob lists run_10 ... (3, 1, 2)", [pieces[2], pieces[0], pieces[1]], ()),
            ("one log, one pass", [one], ()),
            (f"one log, mapping.pass_duration_s={pass_s:g}", [one], (f"mapping.pass_duration_s={pass_s}",))]
    reference = work / "map_0" / "map.pgm"
    for k, (name, logs, sets) in enumerate(rows):
        out = work / f"map_{k}"
        own_frame = pose_source not in ("auto", "reference")
        result = mapped(list(logs), out, work / "map_0" if own_frame and k > 0 else None, *sets,
                        f"mapping.pose_source={pose_source}")
        if own_frame and k == 0:
            result = f"{len(read_door_set(out))} doors (in the odometry's frame)"
        same = (out / "map.pgm").is_file() and (out / "map.pgm").read_bytes() == reference.read_bytes()
        print(f"{name}: {result}; map.pgm {'identical' if same else 'differs'}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=None)
    parser.add_argument("--pass-s", type=float, default=47.0)
    parser.add_argument("--pose-source", default="auto", choices=["auto", "reference", "odometry", "scanmatch"])
    args = parser.parse_args()
    if args.work is None:
        with tempfile.TemporaryDirectory() as tmp:
            run(Path(tmp), args.pass_s, args.pose_source)
    else:
        args.work.mkdir(parents=True, exist_ok=True)
        run(args.work, args.pass_s, args.pose_source)
