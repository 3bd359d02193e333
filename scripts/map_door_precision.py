"""The door maps `doorbatch map` writes with its default stages (grid, then em when the logs have colours), scored
against the simulator's truth on sites not used while developing the em stage.

For each WORLD:SEED: simulate the ``mapping_pass`` scenario into ``--work`` (unless its logs are there), run
``doorbatch map`` on the passes and ``doorbatch evaluate MAPDIR --world TRUTH`` on the result, and print one
row: doors detected, precision (a detection that matches no truth door within ``evaluate.door_match_max_hinge_m``
is a false positive; em maps may report doors that never moved), recall of the doors seen moving and of those
that never moved, and the mean hinge and opening-range errors of the matches.

Usage::

    python scripts/map_door_precision.py [--work DIR] [--site WORLD:SEED ...] [--set section.key=value ...]

Sites by default: the bundled sample, office_corridor seeds 5, 6, 7, l_corridor seed 5, double_door seed 5.
"""

from __future__ import annotations

import argparse
import math
import tempfile
from pathlib import Path

from gridmap_acceptance import Site, _fmt, sample_site, simulated_site

from doorbatch.cli import main as doorbatch
from doorbatch.io.parquet import read_table

DEFAULT_SITES = ("office_corridor:5", "office_corridor:6", "office_corridor:7", "l_corridor:5", "double_door:5")
COLUMNS = ("doors_detected", "door_precision", "door_recall_moved", "door_recall_never_moved",
           "door_hinge_error_mean", "door_range_error_mean")


def score_site(site: Site, out: Path, sets: list[str]) -> dict[str, float | None]:
    """Map the site's passes with the default stages and score the door map against its truth (None: no value,
    e.g. no match to take an error from)."""
    overrides = [a for s in sets for a in ("--set", s)]
    mapdir, report = out / "map", out / "evaluate"
    if doorbatch(["map", *map(str, site.logs), "-o", str(mapdir), "-q", *overrides]) != 0:
        raise SystemExit(f"doorbatch map failed on {site.name}")
    if doorbatch(["evaluate", str(mapdir), "--world", str(site.truth), "-o", str(report), "-q", *overrides]) != 0:
        raise SystemExit(f"doorbatch evaluate failed on {site.name}")
    metrics = read_table("metrics", report / "metrics.parquet").to_pydict()
    return {m: None if math.isnan(v) else v for m, v in zip(metrics["metric"], metrics["value"], strict=True)
            if m in COLUMNS}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--work", type=Path, help="folder for the simulated logs and the maps (kept)")
    parser.add_argument("--site", action="append", help="WORLD:SEED instead of the default sites")
    parser.add_argument("--set", action="append", default=[], dest="sets", help="config override, section.key=value")
    args = parser.parse_args()
    print("| site | doors detected | precision | recall, moved | recall, never moved | hinge error mean (m) "
          "| range error mean (°) |")
    print("|" + "---|" * 7)
    with tempfile.TemporaryDirectory(prefix="map_door_precision_") as tmp:
        work = args.work or Path(tmp)
        for site in [sample_site(), *(simulated_site(spec, work) for spec in args.site or DEFAULT_SITES)]:
            folder = work / "maps" / site.name.split(" ")[0].replace(":", "_")
            r = score_site(site, folder, args.sets)
            print(f"| {site.name} | {_fmt(r['doors_detected'], 0)} | {_fmt(r.get('door_precision'), 2)} "
                  f"| {_fmt(r.get('door_recall_moved'), 2)} | {_fmt(r.get('door_recall_never_moved'), 2)} "
                  f"| {_fmt(r.get('door_hinge_error_mean'), 3)} "
                  f"| {_fmt(None if (e := r.get('door_range_error_mean')) is None else math.degrees(e), 1)} |",
                  flush=True)


if __name__ == "__main__":
    main()
