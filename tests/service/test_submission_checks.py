"""Everything that can be known before work starts is refused at submission, 422 naming the field: strict
types (a string or a boolean for a number, a number for a switch), non-ASCII digits in G-code, a program
without motion or spindle, an unknown material, a NaN or infinity in a scan; no answer names a server path.
In process (TestClient); every case is refused before a job is queued."""
from __future__ import annotations

import pytest

from .conftest import HEADERS, ROBOT_FRICTION

SIM = {"program": "iso160", "pose_set": "iso160", "select": ["near"], "friction": ROBOT_FRICTION}
CIRCLE = {"pose_set": "iso320", "pose": "pose1", "friction": ROBOT_FRICTION}
COMP = {"program": "iso160", "pose_set": "iso160", "pose": "near", "friction": ROBOT_FRICTION}
SEARCH = {"program": "iso160", "pose_set": "iso160", "select": ["near"]}
EXPLAIN = {"scan_csv": "feature,x,y,z\ncircle,0,0,0\n", "program": "iso160", "pose_set": "iso160", "pose": "near"}
RECORD = "t,q,tau\n" + "".join(f"{i * 0.002:.3f},{i * 1e-3:.4f},0.1\n" for i in range(50))
DIAGNOSE = {"train_csv": RECORD, "test_csv": RECORD}
PREDICT = {"model": {"axis": 1}, "t": [0.0, 0.001], "q": [0.0, 0.1]}
INLINE_POSE = [{"name": "p", "xyz": [1.5, 0.0, -0.1], "rpy": [0, 0, 0]}]


def _fields(r) -> list[str]:
    detail = r.json()["detail"]
    return [d["field"] for d in detail] if isinstance(detail, list) else [detail.get("field")]


#: (route, body, the field with the wrong type) for a string, a boolean and (switches) a number.
WRONG_TYPES = [
    ("/simulations", {**SIM, "options": {"spacing_mm": "5"}}, "options.spacing_mm"),
    ("/simulations", {**SIM, "options": {"spacing_mm": True}}, "options.spacing_mm"),
    ("/simulations", {**SIM, "options": {"deflection": 1}}, "options.deflection"),
    ("/simulations", {**SIM, "options": {"shares": "true"}}, "options.shares"),
    ("/simulations", {"program": "iso160", "poses": [{**INLINE_POSE[0], "xyz": ["1.5", 0, -0.1]}]}, "poses.0.xyz.0"),
    ("/simulations", {**SIM, "friction": [{"axis": "1", "model": "robot"}]}, "friction.0.axis"),
    ("/circles", {**CIRCLE, "options": {"radius_mm": "50"}}, "options.radius_mm"),
    ("/circles", {**CIRCLE, "options": {"feed_mm_min": False}}, "options.feed_mm_min"),
    ("/circles", {**CIRCLE, "options": {"center_mm": [0, "0", 0]}}, "options.center_mm.1"),
    ("/circles", {**CIRCLE, "options": {"cw": 0}}, "options.cw"),
    ("/compensations", {**COMP, "options": {"iterations": "2"}}, "options.iterations"),
    ("/compensations", {**COMP, "options": {"iterations": True}}, "options.iterations"),
    ("/compensations", {**COMP, "options": {"iterations": 2.0}}, "options.iterations"),
    ("/compensations", {**COMP, "options": {"check_scales": ["1.2"]}}, "options.check_scales.0"),
    ("/placement-searches", {**SEARCH, "options": {"budget_s": "600"}}, "options.budget_s"),
    ("/placement-searches", {**SEARCH, "options": {"seed": True}}, "options.seed"),
    ("/explain", {**EXPLAIN, "spacing_mm": True}, "spacing_mm"),
    ("/explain", {**EXPLAIN, "max_sims": "3"}, "max_sims"),
    ("/diagnose", {**DIAGNOSE, "seed": "1"}, "seed"),
    ("/diagnose", {**DIAGNOSE, "generations": True}, "generations"),
    ("/friction/predict", {**PREDICT, "t": ["0", "0.001"]}, "t.0"),
    ("/friction/predict", {**PREDICT, "model": {"axis": True}}, "model.axis"),
]


@pytest.mark.parametrize(("route", "body", "field"), WRONG_TYPES, ids=[f"{r}:{f}" for r, _, f in WRONG_TYPES])
def test_a_wrong_type_is_refused_naming_the_field(client, route, body, field):
    r = client.post(route, headers=HEADERS, json=body)
    assert r.status_code == 422, r.text
    assert field in _fields(r), r.text


def test_an_integer_is_still_a_number(client):
    """Strict mode does not refuse a JSON integer for a float field: the circle answers past the schema."""
    r = client.post("/circles", headers=HEADERS, json={**CIRCLE, "options": {"radius_mm": 1500}})
    assert r.status_code == 422 and _fields(r) == ["options.radius_mm"]   # out of reach, not a type error
    assert "reach" in r.json()["detail"]["message"] or "limit" in r.json()["detail"]["message"], r.text


def test_the_view_link_lifetime_is_strict(client):
    r = client.post("/simulations/" + "0" * 32 + "/view-link", headers=HEADERS, json={"expires_s": "60"})
    assert r.status_code == 422 and "expires_s" in _fields(r)


GCODE_HEAD = "G21 G90 G17\nS12000 M3\nG0 X0 Y0 Z5\n"


@pytest.mark.parametrize("route, base", [("/simulations", {"stock": "iso160", "pose_set": "iso160"}),
                                         ("/compensations", {"stock": "iso160", "pose_set": "iso160", "pose": "near"}),
                                         ("/placement-searches", {"stock": "iso160", "pose_set": "iso160"}),
                                         ("/explain", {**EXPLAIN, "program": None, "stock": "iso160"})])
def test_programs_that_cannot_run_are_refused_at_submission(client, route, base):
    base = {k: v for k, v in base.items() if v is not None}
    # Arabic-Indic digits read as numbers by Python, never by a controller: line 4, column 5
    r = client.post(route, headers=HEADERS, json={**base, "gcode": GCODE_HEAD + "G1 X\u0661\u0660 Y0 Z0 F300\n"})
    d = r.json()["detail"]
    assert r.status_code == 422 and d["field"] == "gcode" and (d["line"], d["column"]) == (4, 5), r.text
    assert "U+0661" in d["message"]
    for empty in ["", "\n\n", "(only a comment)\n; and another\n", "G21 G90 G17\nS12000 M3\n"]:
        r = client.post(route, headers=HEADERS, json={**base, "gcode": empty})
        assert r.status_code == 422 and r.json()["detail"]["field"] == "gcode", (empty, r.text)
        assert "no motion" in r.json()["detail"]["message"]
    r = client.post(route, headers=HEADERS, json={**base, "gcode": "G21 G90\nG0 X0 Y0 Z5\nG1 X10 Y0 Z0 F300\n"})
    d = r.json()["detail"]
    assert r.status_code == 422 and d["field"] == "gcode" and "spindle" in d["message"], r.text
    assert "--" not in d["message"]   # no CLI flag named to a service client


def test_unknown_material_is_refused_at_submission(client):
    r = client.post("/simulations", headers=HEADERS, json={**SIM, "options": {"material": "Unobtainium"}})
    d = r.json()["detail"]
    assert r.status_code == 422 and d["field"] == "options.material" and "Al7075" in d["message"], r.text
    assert d["source"] == "materials.toml"


@pytest.mark.parametrize(("scan", "field", "row"), [
    ("feature,x,y,z\ncircle,0,0,0\ncircle,nan,0,0\n", "x", 2), ("feature,x,y,z\ncircle,0,inf,0\n", "y", 1),
    ("feature,x,y,z\ncircle,0,0,-Infinity\n", "z", 1), ("feature,x,y,z\ncircle,0,0,\n", "z", 1),
    ("feature,x,y,z\ncircle,0,0.1.2,0\n", "y", 1)])
def test_scan_values_must_be_finite_numbers(client, scan, field, row):
    r = client.post("/explain", headers=HEADERS, json={**EXPLAIN, "scan_csv": scan})
    d = r.json()["detail"]
    assert r.status_code == 422 and (d["source"], d["field"], d["row"]) == ("scan.csv", field, row), r.text


def test_answers_never_name_server_paths(client):
    from identify.errors import InputError
    from service.app import public_error
    from service.jobs import owner_of
    from service.paths import DATA_DIR
    from service.states import JobKind, JobState

    from .conftest import KEY

    root = str(DATA_DIR.parent)
    assert public_error({"message": "m", "source": f"{root}/data/programs/x.nc"})["source"] == "x.nc"
    assert public_error({"message": f"bad {root}/data/x.toml", "source": "gcode"}) == {"message": "bad data/x.toml",
                                                                                   "source": "gcode"}
    # a job that failed in its worker with a path in the error: the status names the file only
    store = client.app.state.store
    rec = store.create(JobKind.circle, {}, "b", owner=owner_of(KEY))
    store.finish(rec.id, "b", JobState.failed, error=InputError("broken", source="/tmp/greybench-x/program.nc",
                                                                line=3).to_dict())
    err = client.get(f"/circles/{rec.id}", headers=HEADERS).json()["error"]
    assert err == {"message": "broken", "source": "program.nc", "line": 3}
    for route, body in [("/simulations", {**SIM, "options": {"material": "nope"}}),
                        ("/simulations", {**SIM, "robot": "nope"}), ("/circles", {**CIRCLE, "pose": "nope"})]:
        text = client.post(route, headers=HEADERS, json=body).text
        assert root not in text and "/data/" not in text, text
