import pytest

from swingar_pyg.eval.stability import SMALL, available_cases, run_stability, stability_table

pytest.importorskip('anny')


def test_every_stage_is_finite_or_raises_a_clear_error_on_hard_input():
    rows = run_stability(SMALL, progress=False)
    cases = available_cases()
    assert len(rows) == len(cases)
    bad = [row for row in rows if not row.ok]
    assert not bad, stability_table(bad)
    # the measured references, not just finiteness
    by_case = {(row.component, row.case): row for row in rows}
    assert by_case['FCAConv', 'input x 1e3'].value < 1e-5
    assert by_case['FCAConv', 'disconnected pieces (1 : 1e3 scale)'].value < 1e-6
    assert by_case['descriptor', 'N < z (30 vertices, z = 256)'].value < 1e-9
    assert by_case['descriptor', 'disconnected pieces'].value < 0.05
    assert by_case['simulator', 'compliance 0 (stretch, distance bending)'].value < 0.05
    assert by_case['estimator', 'long stream (drift)'].value < 0.01  # mm
    assert by_case['collisions', 'front split through a hip-carried skirt'].value < 0.5
    assert sum(row.outcome == 'raises' for row in rows) == sum(c.raises is not None
                                                               for c in cases)
    assert '| FCAConv | bfloat16 | finite |' in stability_table(rows)
