"""Mutation check of the test suite: each mutant of scripts/mutants.json changes one piece of an algorithm, and
the tests named with it must fail (a test that cannot fail is a defect).

A mutant is its source file, the code text it replaces (``old``, found exactly once) and the text it puts there
(``new``); ``expect: survives`` marks one found equivalent or judged not worth a test, with ``why``. The 165
mutants come from a review of the algorithm modules (2026-11-27); add one with each test written to kill it.

Each mutant is applied to a copy of the working tree (tracked and untracked files, as ``git ls-files`` lists
them) and its tests run there with ``PYTHONPATH`` on the copy; the copy is restored after each.

Run: ``python scripts/mutation_check.py [--only ID ...] [--prefix doorbatch/pipeline/localize/]`` (about 10–30 s
a mutant on two cores; all of them take about an hour). Exit 1 when a mutant expected to be killed survives or no
longer applies (its ``old`` text is gone: update the file).
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

REPO = Path(__file__).resolve().parents[1]


def _copy_tree(dest: Path) -> None:
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard"], cwd=REPO, check=True,
                           capture_output=True, text=True).stdout.splitlines()
    for name in files:
        source = REPO / name
        if source.is_file():
            target = dest / name
            target.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, target)


def _run(copy: Path, mutant: dict[str, object]) -> tuple[str, str]:
    """(status, detail): killed, survived or stale."""
    path = copy / str(mutant["file"])
    original = path.read_text()
    old, new = str(mutant["old"]), str(mutant["new"])
    if original.count(old) != 1:
        return "stale", f"the old text occurs {original.count(old)} times in {mutant['file']}"
    path.write_text(original.replace(old, new))
    try:
        env = dict(os.environ, PYTHONPATH=str(copy))
        tests = [str(t) for t in mutant["tests"]]  # type: ignore[attr-defined]
        proc = subprocess.run([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:warnings", "-p",
                               "no:cacheprovider", *tests], cwd=copy, env=env, capture_output=True, text=True)
        failed = [line for line in proc.stdout.splitlines() if line.startswith("FAILED")]
        if proc.returncode == 1:
            return "killed", failed[0] if failed else "failed"
        if proc.returncode == 0:
            return "survived", ""
        return "killed", f"pytest exit {proc.returncode}"  # collection or import error: the mutant broke it
    finally:
        path.write_text(original)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mutants", type=Path, default=REPO / "scripts" / "mutants.json")
    ap.add_argument("--only", nargs="*", default=None, help="mutant ids")
    ap.add_argument("--prefix", default="", help="only mutants of files under this path")
    args = ap.parse_args()
    mutants = [m for m in json.loads(args.mutants.read_text())
               if str(m["file"]).startswith(args.prefix) and (args.only is None or m["id"] in args.only)]
    bad = 0
    with tempfile.TemporaryDirectory(prefix="doorbatch-mutants-") as tmp:
        copy = Path(tmp)
        _copy_tree(copy)
        for m in mutants:
            start = time.perf_counter()
            status, detail = _run(copy, m)
            expected = "survived" if m.get("expect") == "survives" else "killed"
            ok = status == expected
            bad += not ok
            note = m.get("why", "") if status == "survived" else detail
            print(f"{'ok ' if ok else 'BAD'} {m['id']:6s} {status:8s} {time.perf_counter() - start:5.1f} s  "
                  f"{m['file']}  {note}", flush=True)
    print(f"{len(mutants)} mutants, {bad} not as expected")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
