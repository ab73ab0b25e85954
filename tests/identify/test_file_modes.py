"""Atomically written outputs get the mode an ordinary open()/mkdir() would give under the umask
(0644/0755 under 022), not the 0600/0700 of their temporary files."""
import os
import stat

import numpy as np
import pandas as pd
import pytest

from identify.files import current_umask
from identify.models import make_model
from identify.records import record_from_arrays, write_table
from simulate.robot.model import load_robot, save_robot
from simulate.robot.tables import write_table as write_robot_table

DATA = __import__("pathlib").Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(params=[0o022, 0o027])
def umask(request):
    old = os.umask(request.param)
    yield request.param
    os.umask(old)


def mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def test_current_umask_reads_the_process_umask(umask):
    assert current_umask() == umask


def test_outputs_follow_the_umask(umask, tmp_path):
    frame = pd.DataFrame({"a": [1.0, 2.0]})
    files = [write_table(frame, tmp_path / "t.csv"), write_table(frame, tmp_path / "t.parquet"),
             write_robot_table(frame, tmp_path / "r.csv"),
             save_robot(load_robot(DATA / "robots" / "max100.toml"), tmp_path / "robot.toml")]
    for f in files:
        assert mode(f) == 0o666 & ~umask, f
    t = np.arange(500) * 1e-3
    qd = np.cos(2 * np.pi * t)
    rec = record_from_arrays(t, np.sin(2 * np.pi * t) / (2 * np.pi), 0.5 * np.sign(qd) + 0.1 * qd, qd=qd,
                             qdd=-2 * np.pi * np.sin(2 * np.pi * t))
    folder = make_model("coulomb-viscous").fit(rec).save(tmp_path / "model")
    assert mode(folder) == 0o777 & ~umask
    assert mode(folder / "params.json") == 0o666 & ~umask
