"""Running the DAG of steps on a ``concurrent.futures`` executor (in process, a process pool, or Dask's).

A step is submitted as soon as every step it waits for has ended: with the steps it ``uses`` that
succeeded, or blocked without running when a step it ``needs`` did not succeed.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, BrokenExecutor, Executor, Future, wait

from doorbatch.pipeline.batch.plan import Step
from doorbatch.pipeline.batch.steps import BatchJob, StepOutcome, StepStatus, execute_step


def _blocked(step: Step, outcomes: dict[str, StepOutcome]) -> StepOutcome | None:
    failed = [d for d in step.needs if not outcomes[d].ok]
    if not failed:
        return None
    return StepOutcome(step.id, StepStatus.BLOCKED, error=f"not run: {', '.join(failed)} did not succeed")


def _failed(step: Step, err: BaseException) -> StepOutcome:
    """A step whose worker died (a crashed pool process, a lost Dask worker)."""
    return StepOutcome(step.id, StepStatus.FAILED, error=f"worker failed ({type(err).__name__}: {err})")


def run_steps(steps: Sequence[Step], job: BatchJob, executor: Executor,
              on_outcome: Callable[[Step, StepOutcome], object] = lambda s, o: None,
              on_start: Callable[[Step], object] = lambda s: None) -> dict[str, StepOutcome]:
    """Run ``steps`` (dependencies listed first) on ``executor``; return each step's outcome by id.

    ``on_start`` and ``on_outcome`` are called in this process (progress bars, run.log). An interruption
    (``KeyboardInterrupt``) propagates; the caller shuts the executor down.
    """
    by_id = {s.id: s for s in steps}
    waiting = list(steps)
    running: dict[Future[StepOutcome], Step] = {}
    outcomes: dict[str, StepOutcome] = {}

    def finish(step: Step, outcome: StepOutcome) -> None:
        outcomes[step.id] = outcome
        on_outcome(step, outcome)

    while waiting or running:
        ready = [s for s in waiting if all(d in outcomes for d in s.deps)]
        for step in ready:
            waiting.remove(step)
            blocked = _blocked(step, outcomes)
            if blocked is not None:
                finish(step, blocked)
                continue
            usable = [by_id[u] for u in step.uses if outcomes[u].ok]
            on_start(step)
            try:
                running[executor.submit(execute_step, step, job, usable)] = step
            except BrokenExecutor as err:  # a worker died (killed for memory): the steps left fail, the batch ends
                finish(step, _failed(step, err))
        if not running:
            continue
        done, _ = wait(running, return_when=FIRST_COMPLETED)
        for future in done:
            step = running.pop(future)
            try:
                outcome = future.result()
            except KeyboardInterrupt:
                raise
            except BaseException as err:  # the worker, not the step, failed
                outcome = _failed(step, err)
            finish(step, outcome)
    return outcomes
