"""The time budget of one check: a deadline every stage consults, so that a check time limit
bounds the whole check (validation, geometry, solves, the search of holds), not only its
solver calls.

The deadline is held in a context variable, not passed as an argument: the stages that
consult it lie deep in code shared with analyses that need no bound (posing a mesh, detecting
contacts, one solve), and a context variable belongs to one thread, so concurrent checks in a
node's executor threads each keep their own. The pipeline names its stages (:func:`stage`);
code calls :func:`checkpoint` between steps and inside its long loops, and past the deadline
it raises :class:`CheckTimeout` naming the stage, which the pipeline turns into a
SOLVER_FAILED report.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from contextvars import ContextVar
from typing import NamedTuple


class CheckTimeout(Exception):
    """The check ran past its time limit; ``stage`` is where it was noticed."""

    def __init__(self, stage: str, limit: float):
        super().__init__(f"time limit of {limit:g} s exceeded in the {stage} stage")
        self.stage = stage
        self.limit = limit


class _Deadline(NamedTuple):
    end: float          # time.perf_counter() at which the budget is spent
    limit: float        # s, as given (for the message)


_DEADLINE: ContextVar[_Deadline | None] = ContextVar("rbe_check_deadline", default=None)
_STAGE: ContextVar[str] = ContextVar("rbe_check_stage", default="check")


@contextmanager
def time_budget(limit: float):
    """Work inside the block must end within ``limit`` seconds (inf: no bound). Inside an
    enclosing budget the earlier deadline applies."""
    outer = _DEADLINE.get()
    token = None
    if math.isfinite(limit):
        end = time.perf_counter() + limit
        if outer is None or end < outer.end:
            token = _DEADLINE.set(_Deadline(end, limit))
    try:
        yield
    finally:
        if token is not None:
            _DEADLINE.reset(token)


def remaining() -> float:
    """Seconds left of the current budget (inf without one; may be negative)."""
    deadline = _DEADLINE.get()
    return math.inf if deadline is None else deadline.end - time.perf_counter()


@contextmanager
def stage(name: str):
    """Name the stage of the check that runs inside the block (for :class:`CheckTimeout`)."""
    token = _STAGE.set(name)
    try:
        yield
    finally:
        _STAGE.reset(token)


def checkpoint() -> None:
    """Raise :class:`CheckTimeout` naming the current stage if the budget is spent."""
    deadline = _DEADLINE.get()
    if deadline is not None and time.perf_counter() > deadline.end:
        raise CheckTimeout(_STAGE.get(), deadline.limit)
