"""The stability suite: every public stage on stiff, extreme and degenerate input.

Each case runs one stage (FCAConv, the spectral descriptor, the cloth simulator,
the estimator, collision handling) on one hard input and either gives finite
output, measured against an independent reference where there is one, or must
raise a clear :class:`ValueError`. Finite is not enough where a case has a
``bound``: its measure must stay within it (float32 against float64 within a few
roundoffs, the simulator's strain below 100 %, where an edge twice its rest
length is torn cloth rather than stretched cloth). A row whose output is not
finite, beyond its bound, or that fails otherwise, is a bug (``outcome`` says
which); :func:`run_stability` never hides one. A case whose input is known to
take a stage beyond its bound names the reason in ``limitation``; such a row is
``degraded``, reported as such, and not a bug.

Sizes: :data:`SMALL` runs in well under a minute (the tests), :data:`FULL` at the
sizes of real use (the report): 10k-vertex graphs, a 1.5k-vertex skirt simulated
for seconds, a 10 000-frame stream.

Modules: ``context`` (the sizes and the inputs the cases share), ``records``
(a case, a row, its outcome), one module per family of cases (``cases_geometry``:
FCAConv and the descriptor, ``cases_simulation``, ``cases_estimator``,
``cases_collision``, ``cases_errors``: the cases that must raise) and ``runner``
(the cases in order, running them, the table and the summary).
"""

from swingar_pyg.eval.stability.cases_collision import INSIDE_PERCENT, SURFACE_TOLERANCE
from swingar_pyg.eval.stability.cases_estimator import BF16_MM, DRIFT_MM
from swingar_pyg.eval.stability.cases_geometry import BFLOAT16, EXACT, FLOAT16, FLOAT32, NYSTROM
from swingar_pyg.eval.stability.cases_simulation import TORN
from swingar_pyg.eval.stability.context import FULL, SMALL, StabilityContext, StabilitySizes
from swingar_pyg.eval.stability.records import Case, Outcome, StabilityRow
from swingar_pyg.eval.stability.runner import (
                                               CASES,
                                               as_dicts,
                                               available_cases,
                                               run_case,
                                               run_stability,
                                               stability_summary,
                                               stability_table,
)

__all__ = [
    "BF16_MM", "BFLOAT16", "CASES", "DRIFT_MM", "EXACT", "FLOAT16", "FLOAT32", "FULL",
    "INSIDE_PERCENT", "NYSTROM", "SMALL", "SURFACE_TOLERANCE", "TORN", "Case", "Outcome",
    "StabilityContext", "StabilityRow", "StabilitySizes", "as_dicts", "available_cases",
    "run_case", "run_stability", "stability_summary", "stability_table",
]
