"""``rank-poses --json`` (and ``ranking.json``): every numeric field names its unit, form rows carry
no nominal size, and ``explain --measured`` reads such a file (and the unit-less files of older
versions) back into metres."""
import json
import math

import pytest

from simulate.evaluation.features import TABLE2, FeatureRow, FeatureTable
from simulate.evaluation.ranking import PoseResult, RankEntry, Ranking, ranking_json
from simulate.explain.measured import read_measured_table
from simulate.pipeline import Components
from simulate.toolpath.placement import Placement

NOMINAL = {"circle diameter": (0.108, "m"), "slope angle": (math.radians(5.0), "rad"),
           "circle height zMZ": (0.006, "m")}


def _table(dev_um: float) -> FeatureTable:
    rows = []
    for i, (name, tol) in enumerate(TABLE2):
        nominal, unit = NOMINAL.get(name, (None, ""))
        rows.append(FeatureRow(name, nominal, unit, tol, (dev_um + i) * 1e-6))
    return FeatureTable(rows)


def _ranking() -> Ranking:
    tables = {"near": _table(1.0), "far": _table(-30.0)}
    results = {p: PoseResult(pose=p, components=Components(), table=t, scan=None) for p, t in tables.items()}
    places = [Placement(p, [1.5, 0, 0], [0, 0, 0]) for p in tables]
    entries = [RankEntry("near", tables["near"].score, tables["near"].n_in_tolerance, 1),
               RankEntry("far", tables["far"].score, tables["far"].n_in_tolerance, 2)]
    return Ranking(entries=entries, results=results, variants={}, placements=places)


def _numeric_keys(obj, path=""):
    if isinstance(obj, dict):
        for k, v in obj.items():
            if (isinstance(v, (int, float)) and not isinstance(v, bool) or v is None
                    or isinstance(v, dict) and all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                   for x in v.values())):
                yield path + k
            else:
                yield from _numeric_keys(v, path + k + ".")
    elif isinstance(obj, list):
        for v in obj:
            yield from _numeric_keys(v, path)


def test_fields_carry_units_and_form_rows_have_no_nominal():
    doc = ranking_json(_ranking())
    assert "unit" not in doc
    keys = set(_numeric_keys(doc))
    # dimensionless: the score (sum of |deviation| / tolerance), counts and the rank
    assert keys == {"ranking.rank", "ranking.score", "ranking.in_tolerance", "features.nominal_mm",
                    "features.nominal_deg", "features.tolerance_mm", "features.deviation_mm"}
    rows = {f["name"]: f for f in doc["features"]}
    assert rows["circle diameter"]["nominal_mm"] == pytest.approx(108.0)
    assert rows["circle diameter"]["nominal_deg"] is None
    assert rows["slope angle"]["nominal_deg"] == pytest.approx(5.0) and rows["slope angle"]["nominal_mm"] is None
    for form in ("circle roundness", "square straightness (4x)", "slope straightness"):
        assert rows[form]["nominal_mm"] is None and rows[form]["nominal_deg"] is None
        assert rows[form]["nominal_text"] == "-"
    assert rows["circle diameter"]["tolerance_mm"] == pytest.approx(0.020)
    assert rows["circle diameter"]["deviation_mm"] == {"near": pytest.approx(0.002), "far": pytest.approx(-0.029)}
    assert [e["pose"] for e in doc["ranking"]] == ["near", "far"]


def test_explain_reads_the_new_and_the_old_table(tmp_path):
    new = tmp_path / "ranking.json"
    new.write_text(json.dumps(ranking_json(_ranking()), indent=1))
    t = read_measured_table(new, "far")
    assert t.deviations["circle diameter"] == pytest.approx(-29e-6)      # mm in the file, m inside
    assert t.deviations["slope angle"] == pytest.approx(-21e-6)
    old = tmp_path / "old.json"
    old.write_text(json.dumps({"features": [{"name": "circle diameter", "nominal": 108.0, "tolerance": 0.02,
                                             "deviation": {"near": 0.011}}], "unit": "mm"}))
    assert read_measured_table(old, None).deviations == {"circle diameter": pytest.approx(11e-6)}
    old_m = tmp_path / "old_m.json"
    old_m.write_text(json.dumps({"features": [{"name": "circle diameter", "deviation": 1.1e-5}], "unit": "m"}))
    assert read_measured_table(old_m, None).deviations == {"circle diameter": pytest.approx(11e-6)}
