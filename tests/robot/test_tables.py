"""Robot tables (poses, joints, axis records) through the one table writer, floats exact in CSV."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from identify.errors import InputError
from simulate.robot.tables import JOINT_COLUMNS, read_table, write_table


def _joints(seed: int = 7) -> np.ndarray:
    q = np.random.default_rng(seed).uniform(-np.pi, np.pi, (40, 6))
    q[0] = [0.1, 0.2, 0.1 + 0.2, 1e-300, -0.0, 2.0 / 3.0]   # short decimals, their sums, tiny, signed zero
    q[3, 2] = np.nan                                         # an unreachable pose's joints
    return q


@pytest.mark.parametrize("name", ["q.csv", "q.parquet"])
def test_a_joint_table_reads_back_bit_for_bit(tmp_path, name):
    q = _joints()
    frame = pd.DataFrame(q, columns=list(JOINT_COLUMNS))
    frame["ok"] = ~np.isnan(q).any(axis=1)
    back = read_table(write_table(frame, tmp_path / name))
    np.testing.assert_array_equal(back[list(JOINT_COLUMNS)].to_numpy(float), q)   # NaN where NaN
    assert back["ok"].tolist() == frame["ok"].tolist()
    assert [p.name for p in tmp_path.iterdir()] == [name]                       # no temporary left


def test_csv_floats_are_their_shortest_exact_text(tmp_path):
    path = write_table(pd.DataFrame({"x": [0.1, 0.1 + 0.2, np.nan], "n": [1, 2, 3]}), tmp_path / "t.csv")
    assert path.read_text().splitlines() == ["x,n", "0.1,1", "0.30000000000000004,2", ",3"]


def test_an_unknown_suffix_is_refused_naming_the_file(tmp_path):
    with pytest.raises(InputError, match="unsupported output type") as exc:
        write_table(pd.DataFrame({"x": [1.0]}), tmp_path / "q.txt")
    assert "q.txt" in str(exc.value)
    assert list(tmp_path.iterdir()) == []
