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
