"""Running the suite: every family's cases in report order (:data:`CASES`), the
outcome of one case (:func:`run_case`), a whole run (:func:`run_stability`) and
its summary, Markdown table and plain records."""

from __future__ import annotations

import importlib.util
import math
import time
from dataclasses import asdict

import numpy as np
import torch
from torch import Tensor

from swingar_pyg.eval.stability.cases_collision import COLLISION_CASES
from swingar_pyg.eval.stability.cases_errors import ERROR_CASES
from swingar_pyg.eval.stability.cases_estimator import ESTIMATOR_CASES
from swingar_pyg.eval.stability.cases_geometry import DESCRIPTOR_CASES, FCACONV_CASES
from swingar_pyg.eval.stability.cases_simulation import SIMULATOR_CASES, VBD_CASES
from swingar_pyg.eval.stability.context import FULL, StabilityContext, StabilitySizes
from swingar_pyg.eval.stability.records import Case, Outcome, StabilityRow

CASES: tuple[Case, ...] = (FCACONV_CASES + DESCRIPTOR_CASES + SIMULATOR_CASES + VBD_CASES
                           + ESTIMATOR_CASES + COLLISION_CASES + ERROR_CASES)


def available_cases() -> list[Case]:
    """The cases whose optional packages are installed."""
    return [c for c in CASES if c.needs is None or importlib.util.find_spec(c.needs) is not None]


def _finite(value) -> bool:
    if value is None:
        return True
    if isinstance(value, (list, tuple)):
        return all(_finite(v) for v in value)
    if isinstance(value, Tensor):
        return bool(torch.isfinite(value).all())
    return bool(np.isfinite(np.asarray(value, dtype=np.float64)).all())


def run_case(case: Case, context: StabilityContext) -> StabilityRow:
    """Runs one case; whatever goes wrong is reported in the row, never raised."""
    start = time.perf_counter()
    row = StabilityRow(case.component, case.name, Outcome.FAILED, case.measure, None, case.bound)
    try:
        with torch.no_grad():
            out = case.run(context)
    except ValueError as error:
        row.seconds = time.perf_counter() - start
        expected = case.raises is not None and case.raises in str(error)
        row.outcome = Outcome.RAISES if expected else Outcome.FAILED
        row.note = f"ValueError: {error}"
        return row
    except Exception as error:  # a bug: reported, not hidden
        row.note = f"{type(error).__name__}: {error}"
        row.seconds = time.perf_counter() - start
        return row
    row.seconds = time.perf_counter() - start
    if case.raises is not None:
        row.outcome = Outcome.DID_NOT_RAISE
        return row
    value, outputs, *note = out
    row.value = float(value)
    row.note = note[0] if note else ""
    if not (_finite(outputs) and math.isfinite(row.value)):
        row.outcome = Outcome.NON_FINITE
    elif case.bound is None or row.value <= case.bound:
        row.outcome = Outcome.FINITE
    else:
        row.outcome = Outcome.DEGRADED if case.limitation else Outcome.BEYOND_BOUND
        row.note = "; ".join(filter(None, [row.note, f"beyond {case.bound:.3g}: "
                                                     f"{case.limitation or 'a bug'}"]))
    return row


def run_stability(sizes: StabilitySizes = FULL, estimator=None, body_sdf: str | None = None,
                  components: tuple[str, ...] | None = None,
                  progress: bool = True) -> list[StabilityRow]:
    """Runs every case (or those of ``components``) and returns their rows.

    Args:
        sizes: :data:`SMALL` or :data:`FULL`.
        estimator: a trained :class:`~swingar_pyg.models.SwinGarEstimator`
            (default: a small one with random weights).
        body_sdf: a body SDF checkpoint for the collision cases (default: the
            exact SDF).
    """
    context = StabilityContext(sizes, estimator, body_sdf)
    cases = [c for c in available_cases() if components is None or c.component in components]
    if progress:
        from tqdm import tqdm

        cases = tqdm(cases, desc="stability suite", unit="case")
    return [run_case(case, context) for case in cases]


def stability_summary(rows: list[StabilityRow]) -> str:
    """How many rows had each outcome, naming the degraded and the failing ones."""
    def named(some: list[StabilityRow]) -> str:
        return ": " + ", ".join(f"{r.component} / {r.case}" for r in some) if some else ""

    degraded = [row for row in rows if row.outcome == Outcome.DEGRADED]
    bad = [row for row in rows if not row.ok]
    return (f"{len(rows)} cases, {sum(r.outcome == Outcome.FINITE for r in rows)} finite within "
            f"their bounds, {sum(r.outcome == Outcome.RAISES for r in rows)} raising a clear "
            f"ValueError, {len(degraded)} degraded by a documented limitation{named(degraded)}; "
            f"{len(bad)} failing{named(bad)}")


def stability_table(rows: list[StabilityRow]) -> str:
    """The rows as a Markdown table."""
    lines = ["| component | case | outcome | measure | value | bound | note |",
             "|---|---|---|---|---|---|---|"]
    for row in rows:
        value = "" if row.value is None else f"{row.value:.3g}"
        bound = "" if row.bound is None else f"{row.bound:.3g}"
        lines.append(f"| {row.component} | {row.case} | {row.outcome} | {row.measure} | "
                     f"{value} | {bound} | {row.note} |")
    return "\n".join(lines)


def as_dicts(rows: list[StabilityRow]) -> list[dict]:
    """The rows as plain dicts (for CSV and JSON), the outcome as its string."""
    return [{**asdict(row), "outcome": str(row.outcome)} for row in rows]
