"""``rank-poses --friction AXIS=MODEL``: the compensate command's parser; a bad reference or a bad
option exits 2 naming ``--friction`` (or ``friction``) before anything is written."""
import pytest
from typer.testing import CliRunner

from greybench.cli import app
from greybench.support import DATA_DIR

runner = CliRunner()


@pytest.mark.parametrize("spec, expect", [("1=/no/such/model", "--friction"), ("7=x", "friction"),
                                          ("1:x", "friction")])
def test_bad_friction_reference_exits_2_before_work(tmp_path, spec, expect):
    out = tmp_path / "out"
    r = runner.invoke(app, ["rank-poses", "--program", str(DATA_DIR / "programs" / "iso160.nc"), "--poses",
                            str(DATA_DIR / "poses" / "iso160.json"), "--size", "160", "--spacing", "2",
                            "--out", str(out), "--friction", spec])
    assert r.exit_code == 2, r.output
    assert expect in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert not out.exists()
