"""What a generated client sees: readable, unique operation ids, typed ranking rows (in_tolerance,
worst_feature), the job list and the per-kind statuses in the served OpenAPI, and a stored ranking
served with those fields."""
from __future__ import annotations

import re

from .conftest import HEADERS


def _operations(spec: dict) -> dict[tuple[str, str], dict]:
    return {(method, path): op for path, ops in spec["paths"].items() for method, op in ops.items()}


def test_operation_ids_are_readable_and_unique(client):
    ops = _operations(client.get("/openapi.json").json())
    ids = [op["operationId"] for op in ops.values()]
    assert len(ids) == len(set(ids)), sorted(ids)
    for (method, path), op in ops.items():
        oid = op["operationId"]
        # no path or method baked in (FastAPI's default reads submit_simulation_simulations_post)
        assert re.fullmatch(r"[a-z]+(_[a-z]+)*", oid) and not oid.endswith(f"_{method}"), (method, path, oid)
    named = {(m, p): op["operationId"] for (m, p), op in ops.items()}
    assert named[("post", "/simulations")] == "submit_simulation"
    assert named[("get", "/jobs")] == "list_jobs"
    assert named[("delete", "/circles/{job_id}")] == "cancel_circle"
    assert named[("delete", "/compensations/{job_id}")] == "cancel_compensation"
    assert named[("post", "/circles/{job_id}/view-link")] == "circle_view_link"
    assert named[("get", "/simulations/{job_id}/view/workpiece/{pose}/mesh")] == "simulation_view_mesh"


def test_results_are_typed_in_the_schema(client):
    spec = client.get("/openapi.json").json()
    schemas = spec["components"]["schemas"]
    entry = schemas["RankingEntry"]["properties"]
    assert {"integer"} <= {t.get("type") for t in entry["in_tolerance"]["anyOf"]}
    assert {"string"} <= {t.get("type") for t in entry["worst_feature"]["anyOf"]}
    assert set(schemas["JobList"]["required"]) == {"jobs", "total", "limit", "offset"}
    ops = _operations(spec)

    def ok_schema(method, path):
        return ops[(method, path)]["responses"]["200" if method != "post" else "202"]["content"][
            "application/json"]["schema"]["$ref"].rsplit("/", 1)[1]

    assert ok_schema("get", "/circles/{job_id}") == ok_schema("post", "/circles") == "CircleJobStatus"
    assert ok_schema("delete", "/circles/{job_id}") == "CircleJobStatus"
    assert ok_schema("get", "/compensations/{job_id}") == "CompensationJobStatus"
    assert ok_schema("delete", "/compensations/{job_id}") == "CompensationJobStatus"
    assert ok_schema("get", "/jobs") == "JobList"


def test_a_stored_ranking_is_served_with_its_typed_fields(settings):
    from fastapi.testclient import TestClient

    from service.app import create_app

    from .test_reliability import fabricate_finished_job

    job, _ = fabricate_finished_job(settings.data_dir)
    with TestClient(create_app(settings)) as c:
        r = c.get(f"/simulations/{job}/ranking", headers=HEADERS)
    assert r.status_code == 200, r.text
    assert r.json()["ranking"] == [{"pose": "near", "score": 1.25, "rank": 1, "in_tolerance": 9,
                                    "worst_feature": "circle"}]
