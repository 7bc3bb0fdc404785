"""The master algorithms (orchestrator/protocols.py ``Algorithm``): in which order the components
due at one tick go through the three stages of a step (docs/architecture.md, "Master algorithm").

* Gauss-Seidel (the default): one component after the other, in data-flow order, each through
  all three stages, so a consumer in the same macro step sees what its producer has just
  computed (no latency along a chain).
* Jacobi: each stage for every due component before the next stage: all inputs are gathered
  before anything steps, so each hop adds one step of latency (what libcosim's fixed-step
  algorithm does).
"""
from __future__ import annotations

from typing import Any, Dict, Sequence, Union

from orchestrator.protocols import ALGORITHMS, Algorithm, Stages


class GaussSeidel:
    name = "gauss-seidel"

    def step_due(self, due: Sequence[Any], stages: Stages, time_s: float, tick: int) -> None:
        gather, step, conclude = stages.gather, stages.step, stages.conclude
        for component in due:
            gather(component, time_s)
            step(component, time_s)
            conclude(component, tick)


class Jacobi:
    name = "jacobi"

    def step_due(self, due: Sequence[Any], stages: Stages, time_s: float, tick: int) -> None:
        gather, step, conclude = stages.gather, stages.step, stages.conclude
        for component in due:
            gather(component, time_s)
        for component in due:
            step(component, time_s)
        for component in due:
            conclude(component, tick)


#: the algorithms by the names of ``ALGORITHMS`` (the CLI's --algorithm)
BY_NAME: Dict[str, type] = {GaussSeidel.name: GaussSeidel, Jacobi.name: Jacobi}
assert tuple(BY_NAME) == ALGORITHMS


def algorithm(choice: Union[str, Algorithm]) -> Algorithm:
    """An algorithm given by name (``"jacobi"``) or as an object with ``step_due``."""
    if isinstance(choice, str):
        if choice not in BY_NAME:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}")
        return BY_NAME[choice]()
    if not callable(getattr(choice, "step_due", None)):
        raise ValueError(f"an algorithm needs a step_due method: {choice!r}")
    return choice
