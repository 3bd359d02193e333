"""The DAG of doorbatch run: its steps and dependencies, and how failures block or spare the others."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from doorbatch.config import DoorbatchConfig
from doorbatch.io.dataset import Dataset, Site
from doorbatch.pipeline.batch import scheduler
from doorbatch.pipeline.batch.plan import Step, StepKind, plan_steps
from doorbatch.pipeline.batch.steps import BatchJob, StepOutcome, StepStatus

DATASET = Dataset(Path("/d"), (
    Site("a", (Path("/d/a/m1.mcap"), Path("/d/a/m2.mcap")), (Path("/d/a/l1.mcap"), Path("/d/a/l2.log.gz"))),
    Site("b", (Path("/d/b/m.mcap"),), (Path("/d/b/l1.mcap"),)),
), {})


def test_plan_lists_each_step_after_what_it_waits_for() -> None:
    steps = plan_steps(DATASET, ["mcl", "rbpf"])
    ids = [s.id for s in steps]
    assert len(ids) == len(set(ids)) == 2 + 4 + 2 + 2 + 1  # maps, localize a, localize b, evaluations, report
    for i, step in enumerate(steps):
        assert all(ids.index(d) < i for d in step.deps)
    by_id = {s.id: s for s in steps}
    loc = by_id["localize:a/l2/rbpf"]
    assert loc.needs == ("map:a",) and loc.out_dir == "a/runs/l2/rbpf" and loc.log == Path("/d/a/l2.log.gz")
    assert by_id["evaluate:a"].needs == ("map:a",)
    assert set(by_id["evaluate:a"].uses) == {f"localize:a/{log}/{m}" for log in ("l1", "l2") for m in ("mcl", "rbpf")}
    assert by_id["report"].uses == ("evaluate:a", "evaluate:b") and by_id["report"].out_dir == "report"
    assert {s.kind for s in steps} == set(StepKind)


@pytest.mark.parametrize("workers", [1, 3])
def test_a_failed_map_blocks_its_site_and_the_report_uses_the_other(monkeypatch: pytest.MonkeyPatch,
                                                                    workers: int) -> None:
    seen: dict[str, list[str]] = {}

    def fake_step(step: Step, job: BatchJob, usable: list[Step]) -> StepOutcome:
        seen[step.id] = [u.id for u in usable]
        if step.id == "map:b":
            return StepOutcome(step.id, StepStatus.FAILED, error="corrupt")
        if step.id == "localize:a/l2/mcl":
            raise MemoryError("worker died")  # the executor, not the step, failed
        return StepOutcome(step.id, StepStatus.DONE)

    monkeypatch.setattr(scheduler, "execute_step", fake_step)
    steps = plan_steps(DATASET, ["mcl"])
    job = BatchJob(DATASET, Path("/out"), DoorbatchConfig())
    with ThreadPoolExecutor(workers) as pool:
        outcomes = scheduler.run_steps(steps, job, pool)
    assert set(outcomes) == {s.id for s in steps}
    assert outcomes["localize:b/l1/mcl"].status is StepStatus.BLOCKED
    assert outcomes["evaluate:b"].status is StepStatus.BLOCKED and "map:b" in str(outcomes["evaluate:b"].error)
    assert outcomes["localize:a/l2/mcl"].status is StepStatus.FAILED
    assert "MemoryError" in str(outcomes["localize:a/l2/mcl"].error)
    assert seen["evaluate:a"] == ["localize:a/l1/mcl"]  # evaluates the run that succeeded
    assert seen["report"] == ["evaluate:a"] and outcomes["report"].ok
    assert "localize:b/l1/mcl" not in seen


def test_a_pool_broken_by_a_dead_worker_fails_the_steps_left_not_the_batch(monkeypatch: pytest.MonkeyPatch) -> None:
    """A worker killed for memory breaks a process pool: each later submit raises BrokenProcessPool, which had
    ended the run as an internal error (exit 1, no summary, no report). The steps left fail, every step gets an
    outcome, and the batch ends as a partial one."""
    from concurrent.futures.process import BrokenProcessPool

    def fake_step(step: Step, job: BatchJob, usable: list[Step]) -> StepOutcome:
        return StepOutcome(step.id, StepStatus.DONE)

    class DiesAfterTwo(ThreadPoolExecutor):
        submitted = 0

        def submit(self, fn, /, *args, **kwargs):  # type: ignore[no-untyped-def, override]
            self.submitted += 1
            if self.submitted > 2:
                raise BrokenProcessPool("a child process terminated abruptly")
            return super().submit(fn, *args, **kwargs)

    monkeypatch.setattr(scheduler, "execute_step", fake_step)
    steps = plan_steps(DATASET, ["mcl"])
    with DiesAfterTwo(1) as pool:
        outcomes = scheduler.run_steps(steps, BatchJob(DATASET, Path("/out"), DoorbatchConfig()), pool)
    assert set(outcomes) == {s.id for s in steps}
    done = [o for o in outcomes.values() if o.status is StepStatus.DONE]
    failed = [o for o in outcomes.values() if o.status is StepStatus.FAILED]
    assert len(done) == 2 and failed and all("BrokenProcessPool" in str(o.error) for o in failed)


def test_pool_workers_die_with_a_killed_main_process(tmp_path: Path) -> None:
    """kill -9 of `doorbatch run` (the OOM killer, a cron timeout) left its pool workers orphaned, finishing
    steps into OUT without the lock's holder and then idle for good."""
    import os
    import signal
    import subprocess
    import sys
    import time

    if not sys.platform.startswith("linux"):
        pytest.skip("PR_SET_PDEATHSIG is Linux's")
    script = ("import os, sys, time\n"
              "from doorbatch.pipeline.batch.executors import _process_pool\n"
              "with _process_pool(2) as pool:\n"
              "    futures = [pool.submit(time.sleep, 60) for _ in range(2)]\n"
              "    time.sleep(1.0)\n"
              "    import multiprocessing\n"
              "    print(' '.join(str(c.pid) for c in multiprocessing.active_children()), flush=True)\n"
              "    time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=tmp_path,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[3])})
    assert proc.stdout is not None
    workers = [int(p) for p in proc.stdout.readline().split()]
    assert len(workers) >= 2
    proc.send_signal(signal.SIGKILL)
    proc.wait()

    def alive(pid: int) -> bool:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        stat = Path(f"/proc/{pid}/stat").read_text()  # a zombie waiting for init to reap it is dead
        return stat.split(")")[-1].split()[0] != "Z"

    deadline = time.monotonic() + 10.0
    while any(alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(alive(p) for p in workers)
