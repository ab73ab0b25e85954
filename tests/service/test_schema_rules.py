"""The served /openapi.json states the cross-field rules the request validators enforce: exactly one of
``program`` and ``gcode`` (and of ``pose_set`` and ``poses``), inline G-code needs ``stock``, ``select``
needs ``pose_set``, a pose name needs ``pose_set``; the values route's ``variable`` is an enum. Each rule
is checked by validating bodies with jsonschema against the served schema and comparing with what the
route answers."""
from __future__ import annotations

import jsonschema
import pytest

from .conftest import HEADERS

#: Request schema per route, and bodies: (body, does the route's validator accept it).
BODIES = {
    "/compensations": [({"program": "iso160", "pose_set": "iso160", "pose": "near"}, True),
                       ({"pose_set": "iso160", "pose": "near"}, False),
                       ({"program": "iso160", "gcode": "G0 X0\n", "pose_set": "iso160", "pose": "near"}, False),
                       ({"gcode": "G0 X0\n", "pose_set": "iso160", "pose": "near"}, False),   # no stock
                       ({"program": "iso160", "pose": "near"}, False)],                       # name without set
    "/placement-searches": [({"program": "iso160", "pose_set": "iso160"}, True),
                            ({"pose_set": "iso160"}, False),
                            ({"program": "iso160", "gcode": "G0 X0\n", "pose_set": "iso160"}, False),
                            ({"program": "iso160"}, False),
                            ({"program": "iso160", "pose_set": "iso160",
                              "poses": [{"name": "p", "xyz": [1.5, 0, -0.1], "rpy": [0, 0, 0]}]}, False),
                            ({"gcode": "G0 X0\n", "pose_set": "iso160"}, False),                # no stock
                            ({"program": "iso160", "select": ["near"],
                              "poses": [{"name": "p", "xyz": [1.5, 0, -0.1], "rpy": [0, 0, 0]}]}, False)],
    "/circles": [({"pose_set": "iso320", "pose": "pose1"}, True), ({"pose": "pose1"}, False)],
}


def _request_schema(spec: dict, route: str) -> dict:
    """The route's request body schema, resolvable on its own (components attached)."""
    ref = spec["paths"][route]["post"]["requestBody"]["content"]["application/json"]["schema"]["$ref"]
    return {"$ref": ref, "components": spec["components"]}


@pytest.mark.parametrize("route", list(BODIES))
def test_the_schema_accepts_what_the_validator_accepts(client, route):
    spec = client.get("/openapi.json").json()
    validator = jsonschema.Draft202012Validator(_request_schema(spec, route))
    for body, accepted in BODIES[route]:
        assert validator.is_valid(body) == accepted, (route, body)
        # and the route's own validator agrees (a refused body is 422 before any work)
        if not accepted:
            assert client.post(route, headers=HEADERS, json=body).status_code == 422, (route, body)


def test_program_or_gcode_is_a_oneof_in_every_program_route(client):
    spec = client.get("/openapi.json").json()
    for route in ("/simulations", "/explain", "/compensations", "/placement-searches"):
        name = spec["paths"][route]["post"]["requestBody"]["content"]["application/json"]["schema"]["$ref"]
        rules = spec["components"]["schemas"][name.rsplit("/", 1)[1]]["allOf"]
        one_ofs = [sorted(o["required"][0] for o in r["oneOf"]) for r in rules if "oneOf" in r]
        assert ["gcode", "program"] in one_ofs, route


def test_the_values_variable_is_an_enum_of_the_workpiece_variables(client):
    from service.view import TOOL_DEVIATION, ViewVariable
    from simulate.machining.virtual_workpiece import VARIABLES

    assert [v.value for v in ViewVariable] == [TOOL_DEVIATION, *VARIABLES]
    spec = client.get("/openapi.json").json()
    routes = [p for p in spec["paths"] if p.endswith("/view/workpiece/{pose}/values")]
    assert routes
    for path in routes:
        param = next(p for p in spec["paths"][path]["get"]["parameters"] if p["name"] == "variable")
        schema = param["schema"]
        if "$ref" in schema:
            schema = spec["components"]["schemas"][schema["$ref"].rsplit("/", 1)[1]]
        assert schema["enum"] == [TOOL_DEVIATION, *VARIABLES], path


def test_an_unknown_variable_is_refused_by_the_enum(client):
    """A stored succeeded simulation: the route answers 422 naming ``variable`` before reading any file."""
    from service.jobs import owner_of
    from service.states import JobKind, JobState

    from .conftest import KEY

    store = client.app.state.store
    rec = store.create(JobKind.simulation, {}, "b", owner=owner_of(KEY))
    store.finish(rec.id, "b", JobState.succeeded, result={})
    r = client.get(f"/simulations/{rec.id}/view/workpiece/near/values", headers=HEADERS, params={"variable": "nope"})
    assert r.status_code == 422 and [d["field"] for d in r.json()["detail"]] == ["variable"], r.text
    r = client.get(f"/simulations/{rec.id}/view/workpiece/near/values", headers=HEADERS, params={"variable": "force"})
    assert r.status_code != 422, r.text   # a known variable passes the schema (the workpiece file is missing)
