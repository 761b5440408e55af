import math

import pytest

from swingar_pyg.eval.stability import (
    SMALL,
    Case,
    available_cases,
    run_case,
    run_stability,
    stability_summary,
    stability_table,
)
from tests.extras import require

require('anny')


def test_every_stage_is_finite_within_its_bound_or_raises_a_clear_error_on_hard_input():
    rows = run_stability(SMALL, progress=False)
    cases = available_cases()
    assert len(rows) == len(cases)
    bad = [row for row in rows if not row.ok]
    assert not bad, stability_table(bad)
    limited = {(c.component, c.name) for c in cases if c.limitation}
    assert all((row.component, row.case) in limited for row in rows if row.outcome == 'degraded')
    by_case = {(row.component, row.case): row for row in rows}
    # tighter than the bound: infinitely stiff stretch keeps the cloth near its rest length
    assert by_case['simulator', 'compliance 0 (stretch, distance bending)'].value < 0.05
    assert sum(row.outcome == 'raises' for row in rows) == sum(c.raises is not None
                                                               for c in cases)
    assert '| FCAConv | bfloat16 | finite |' in stability_table(rows)


def _case(value: float, bound: float | None = 1.0, limitation: str = '') -> Case:
    return Case('stage', 'input', 'measure', lambda context: (value, [value]), bound=bound,
                limitation=limitation)


@pytest.mark.parametrize('case, outcome, ok', [
    (_case(0.5), 'finite', True),
    (_case(2.0), 'beyond bound', False),
    (_case(2.0, limitation='known'), 'degraded', True),
    (_case(2.0, bound=None), 'finite', True),
    (_case(math.nan, bound=None), 'non-finite', False),
    (_case(math.inf, limitation='known'), 'non-finite', False),
])
def test_a_finite_value_beyond_its_bound_is_a_bug_unless_the_case_names_its_limitation(
        case, outcome, ok):
    row = run_case(case, context=None)
    assert (row.outcome, row.ok, row.bound) == (outcome, ok, case.bound)
    if outcome == 'degraded':
        assert 'known' in stability_table([row])


def test_the_summary_counts_each_outcome_and_names_the_degraded_and_failing_cases():
    rows = [run_case(case, context=None) for case in
            (_case(0.5), _case(2.0), _case(3.0, limitation='known'), _case(math.nan))]
    rows[2].case = 'limited input'
    assert stability_summary(rows) == (
        '4 cases, 1 finite within their bounds, 0 raising a clear ValueError, 1 degraded by a '
        'documented limitation: stage / limited input; 2 failing: stage / input, stage / input')
