"""Confusion matrix over >= 30 generated cases (slow): right cause >= 95 %, clean -> none >= 95 %."""
import numpy as np
import pytest
from rich.console import Console

from greybench_bench.diagnose import confusion_table
from identify.diagnosis_cases import generated_cases, run_case


@pytest.mark.slow
def test_confusion_matrix_over_generated_cases(trajectories, capsys):
    cases = generated_cases(36, seed=0)
    assert len(cases) >= 30
    rows, ext = [], []
    for effect, ratio, s_tr, s_te in cases:
        res, _ = run_case(effect, ratio, s_tr, s_te, *trajectories)
        rows.append((effect, res.cause.value))
        if effect != "none":
            ext.append(res.extended_test.rmse)
            assert res.gain == pytest.approx(1 - res.extended_test.rmse / res.baseline_test.rmse)
    with capsys.disabled():
        Console().print(confusion_table(rows))
    effects = [(t, p) for t, p in rows if t != "none"]
    clean = [(t, p) for t, p in rows if t == "none"]
    assert clean, "the generator must produce clean records"
    assert sum(t == p for t, p in effects) >= 0.95 * len(effects)
    assert sum(p == "none" for _, p in clean) >= 0.95 * len(clean)
    assert np.median(ext) < 1.1 * 0.02
