"""report.md of a compensation: a stiffness check of a program without Table-2 rows (not a test-piece
stock) has no sums to report; the report leaves it out instead of failing."""
from __future__ import annotations

from simulate.compensation.report import report_text

ITERATION = {"index": 0, "table_sum_mm": None, "score": None, "path_rms_um": 12.0, "path_max_um": 30.0,
             "max_offset_um": 0.0, "time_ratio": 1.0, "speed_ratio": 1.0, "pieces": 3, "wall_time_s": 0.5,
             "rows_worse": None}
INFO = {"evaluation": None, "checks": [None], "best_iteration": 0, "iterations": [ITERATION],
        "max_offset_mm": 0.0, "time_ratio": 1.0, "speed_ratio": 1.0}
CHECK = {"stiffness_scale": 0.8, "sum_before_mm": 0.05, "sum_after_mm": 0.02, "ratio": 0.4, "rows_worse": []}


def test_a_check_without_table_rows_is_left_out():
    text = report_text(None, INFO, "small", 1.0)
    assert "Robustness" not in text and "## Iterations" in text and "| 12.0 |" in text


def test_a_check_with_table_rows_is_reported():
    text = report_text(None, dict(INFO, checks=[None, CHECK]), "small", 1.0)
    assert "## Robustness" in text
    assert "| 0.8 | 50.0 | 20.0 | 0.400 | none |" in text


def test_a_check_of_an_original_without_deviation_has_no_ratio():
    zero = dict(CHECK, sum_before_mm=0.0, sum_after_mm=0.0, ratio=None)
    text = report_text(None, dict(INFO, checks=[None, zero]), "small", 1.0)
    assert "| 0.8 | 0.0 | 0.0 | - | none |" in text
