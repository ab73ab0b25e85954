"""The human output of commands whose tests run them with --json: every figure reaches the tables in
the unit its column names (µm from mm, % from a fraction), and nothing is cut in a pipe."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

from greybench.commands.compensate import print_info
from greybench.commands.explain import print_explanation


def cells(text: str, first: str) -> list[str]:
    """The cells of the table row whose first cell is ``first``."""
    rows = [[c.strip() for c in line.split("│")[1:-1]] for line in text.splitlines() if "│" in line]
    return next(r for r in rows if r and r[0] == first)


def test_compensation_summary_in_micrometres(capsys):
    info = {"evaluation": {"stiffness_scale": 0.8, "ratio": 0.25, "rows_worse": ["slope_straightness"],
                           "rows_mm": [{"name": "circle_roundness", "tolerance": 0.02, "before": 0.0123,
                                        "after": -0.0011}],
                           "sum_before_mm": 0.0456, "sum_after_mm": 0.0114},
            "checks": [None, {"stiffness_scale": 1.2, "sum_before_mm": 0.05, "sum_after_mm": 0.02, "ratio": 0.4}],
            "best_iteration": 3, "max_offset_mm": 0.0372, "time_ratio": 1.001, "speed_ratio": 0.999,
            "files": ["out/compensated.nc", "out/report.md"]}
    print_info(info)
    text = capsys.readouterr().out
    assert cells(text, "circle_roundness") == ["circle_roundness", "20", "+12.3", "-1.1"]
    assert cells(text, "sum |deviation|") == ["sum |deviation|", "", "45.6", "11.4"]
    assert "robot stiffness x0.8" in text
    assert "ratio after/before: 0.250" in text and "slope_straightness" in text
    assert "stiffness x1.2: sum 50.0 -> 20.0 µm, ratio 0.400" in text
    assert "largest offset 37.2 µm" in text and "report: out/report.md" in text


def test_explanation_in_micrometres_and_percent(capsys):
    fit = SimpleNamespace(cause="stiffness:2", score=42.123, heldout_gain=0.5, theta=[1.25e5])
    ex = SimpleNamespace(cause="stiffness:2", choice=SimpleNamespace(ranking=[fit]), rms_before=12e-6, rms_after=3e-6,
                         gain=0.75, rms_by_feature=lambda: {"circle_wall": (10e-6, 2.5e-6)},
                         calibration=SimpleNamespace(before=SimpleNamespace(param="k2", value=1e6, unit="Nm/rad"),
                                                     after=SimpleNamespace(value=8e5)))
    print_explanation(ex, Path("explained"))  # type: ignore[arg-type]
    text = capsys.readouterr().out
    assert cells(text, "stiffness:2") == ["stiffness:2", "42.1", "50.0", "1.25e+05"]
    assert cells(text, "circle_wall") == ["circle_wall", "10.00", "2.50"]
    assert cells(text, "all") == ["all", "12.00", "3.00"]
    assert "calibrated k2: 1e+06 -> 800000 Nm/rad" in text
    assert "gain (1 - rms_after/rms_before): 75.0 %; report explained/report.md" in text


def test_an_error_line_keeps_its_units():
    from typer.testing import CliRunner

    from greybench.cli import app

    res = CliRunner().invoke(app, ["trace", "--workpiece", "nowhere", "--point", "0,109"])
    assert res.exit_code == 2
    assert "field 'point': expected 3 finite comma-separated numbers [mm], got '0,109'" in res.output


def test_circle_spike_table_keeps_every_unit(capsys):
    from greybench.support import print_table
    from simulate.run import spike_table

    spike = SimpleNamespace(angle_deg=92.25, name="A1", height_um=338.7, spike_um=31.4, lost_motion_um=292.3)
    print_table(*spike_table(SimpleNamespace(spikes=[spike])))  # type: ignore[arg-type]
    text = capsys.readouterr().out
    header = [c.strip() for c in next(ln for ln in text.splitlines() if "joint" in ln).split("┃")[1:-1]]
    assert header == ["angle [deg]", "joint", "excursion [µm]", "spike [µm]", "lost motion [µm]"]
    assert cells(text, "92.2") == ["92.2", "A1", "+338.7", "+31.4", "+292.3"]
