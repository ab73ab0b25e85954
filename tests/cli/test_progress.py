"""Progress off a terminal: plain timestamped lines (no ANSI codes, no carriage returns) while the
work runs, a heartbeat when nothing advances; tables in a pipe are never folded or cut."""
import re
import time
from datetime import datetime

from rich.table import Table
from typer.testing import CliRunner

from greybench import support
from greybench.cli import app

STAMP = re.compile(r"^(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d) (.+)$")


def test_plain_lines_with_heartbeat(capsys, monkeypatch):
    monkeypatch.setenv("GREYBENCH_PROGRESS_INTERVAL_S", "0.1")
    with support.progress("slow step", total=2) as advance:
        advance.describe("first half")
        time.sleep(0.8)  # no advance: only the heartbeat writes
        advance(1)
        advance.describe("second half")
        advance(1)
    raw = capsys.readouterr().err
    assert "\x1b" not in raw and "\r" not in raw
    lines = raw.splitlines()
    stamps = [STAMP.match(line) for line in lines]
    assert all(stamps), lines
    times = [datetime.fromisoformat(m.group(1)) for m in stamps]
    assert times == sorted(times)
    texts = [m.group(2) for m in stamps]
    assert texts[0] == "slow step: started, 2 steps"
    beats = [t for t in texts if t.startswith("slow step (first half): 0/2 (0%)")]
    assert len(beats) >= 3  # 0.8 s at a 0.1 s interval, with room for a busy machine
    assert any(t.startswith("slow step (second half): 1/2 (50%)") for t in texts)
    assert texts[-1].startswith("slow step: done in ")


def test_failure_is_reported_and_disabled_is_silent(capsys):
    try:
        with support.progress("doomed"):
            raise RuntimeError("boom")
    except RuntimeError:
        pass
    assert capsys.readouterr().err.splitlines()[-1].split(" ", 1)[1].startswith("doomed: stopped after ")
    with support.progress("quiet", enabled=False) as advance:
        advance(1)
        advance.describe("x")
    assert capsys.readouterr().err == ""


def test_tables_in_a_pipe_are_not_cut(monkeypatch):
    monkeypatch.setenv("COLUMNS", "40")  # a narrow terminal elsewhere must not fold a piped table
    cells = [f"value-{i}-" + "x" * 30 for i in range(6)]

    def show():
        table = Table(title="wide")
        for i in range(6):
            table.add_column(f"column {i} \\[s]")
        table.add_row(*cells)
        support.out.print(table)

    import typer

    cli = typer.Typer()
    cli.command()(show)
    res = CliRunner().invoke(cli, [])
    assert res.exit_code == 0, res.output
    row = [line for line in res.stdout.splitlines() if "value-0-" in line]
    assert len(row) == 1 and all(c in row[0] for c in cells)
    assert "column 5 [s]" in res.stdout


def test_command_progress_off_a_terminal(tmp_path):
    out = tmp_path / "tp.nc"
    prog = tmp_path / "path.csv"
    res = CliRunner().invoke(app, ["testpiece", "--size", "160", "--out", str(out)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["interpolate", "--program", str(out), "--robot", "max100", "--pose",
                                   str(support.DATA_DIR / "poses" / "iso160.json"), "--out", str(prog), "--json"])
    assert res.exit_code == 0, res.output
    lines = res.stderr.splitlines()
    assert all(STAMP.match(line) for line in lines) and "\x1b" not in res.stderr
    assert lines[0].endswith("interpolate: started, 4 steps") and "inverse kinematics" in res.stderr
    assert lines[-1].split(" ", 1)[1].startswith("interpolate: done in ")
