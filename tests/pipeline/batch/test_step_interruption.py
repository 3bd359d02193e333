"""An interruption that Python wrapped into another exception still interrupts the run."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from doorbatch.pipeline.batch import steps


class _InterruptsOnSetName:
    def __set_name__(self, owner: type, name: str) -> None:
        raise KeyboardInterrupt("signal 15")  # what sigterm_as_interrupt raises, here mid-class-creation


def _class_creation_interrupted(*_: Any) -> None:
    type("Interrupted", (), {"field": _InterruptsOnSetName()})  # Python wraps it: RuntimeError("Error calling ...")


def test_a_sigterm_wrapped_by_python_unwinds_as_an_interrupt_not_a_failed_step(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    with pytest.raises(RuntimeError) as wrapped:
        _class_creation_interrupted()
    assert isinstance(wrapped.value.__cause__, KeyboardInterrupt)  # the case CI met on a SIGTERM mid-import
    monkeypatch.setattr(steps, "_inputs", _class_creation_interrupted)
    job = SimpleNamespace(fingerprints={}, config=SimpleNamespace(as_dict=dict), out=tmp_path, force=False)
    step = SimpleNamespace(kind=steps.StepKind.MAP, id="map:s", out_dir="s/map")
    with pytest.raises(KeyboardInterrupt):
        steps.execute_step(step, job)  # type: ignore[arg-type]


def test_a_plain_bug_still_fails_only_its_step(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    def bug(*_: Any) -> None:
        raise RuntimeError("a bug")

    monkeypatch.setattr(steps, "_inputs", bug)
    job = SimpleNamespace(fingerprints={}, config=SimpleNamespace(as_dict=dict), out=tmp_path, force=False)
    step = SimpleNamespace(kind=steps.StepKind.MAP, id="map:s", out_dir="s/map")
    outcome = steps.execute_step(step, job)  # type: ignore[arg-type]
    assert outcome.status is steps.StepStatus.FAILED and "a bug" in (outcome.error or "")
