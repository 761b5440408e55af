"""What the suite is made of: a :class:`Case` (one hard input for one stage) and
the :class:`StabilityRow` it gives, whose :class:`Outcome` says how it went."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import Callable

from swingar_pyg.eval.stability.context import StabilityContext


class Outcome(str, Enum):
    """How a case went. ``finite`` (within the case's bound) and ``raises`` (the
    expected :class:`ValueError`) when all is well, ``degraded`` when beyond a
    bound the case documents as a limitation; the others mark a bug.

    A member equals its string (``Outcome.FINITE == "finite"``) and prints as it."""

    FINITE = "finite"
    RAISES = "raises"
    DEGRADED = "degraded"
    BEYOND_BOUND = "beyond bound"
    NON_FINITE = "non-finite"
    FAILED = "failed"
    DID_NOT_RAISE = "did not raise"

    def __str__(self) -> str:
        return self.value


@dataclass
class StabilityRow:
    """One case's result: ``ok`` unless its ``outcome`` marks a bug."""

    component: str
    case: str
    outcome: Outcome
    measure: str
    value: float | None
    bound: float | None = None
    note: str = ""
    seconds: float = 0.0

    @property
    def ok(self) -> bool:
        return self.outcome in (Outcome.FINITE, Outcome.RAISES, Outcome.DEGRADED)


@dataclass(frozen=True)
class Case:
    """One hard input for one stage.

    ``run`` returns the measure's value, the outputs checked for finiteness and
    optionally a note; ``bound`` is the largest acceptable value (``None``: any
    finite value); ``limitation`` says why this input may go beyond it;
    ``raises`` is the text the expected :class:`ValueError` contains."""

    component: str
    name: str
    measure: str
    run: Callable[[StabilityContext], tuple[float, list]]
    bound: float | None = None
    limitation: str = ""
    raises: str | None = None
    needs: str | None = None  # an optional package the case runs only with
