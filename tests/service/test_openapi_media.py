"""Binary and CSV answers are declared with their media types and a body schema in the served OpenAPI
(a generated client keeps the GLB and file routes and returns their bytes), and report rows are typed."""
from __future__ import annotations


def _ok(spec: dict, path: str) -> dict:
    return spec["paths"][path]["get"]["responses"]["200"]["content"]


def test_file_answers_have_media_types_and_a_binary_schema(client):
    spec = client.get("/openapi.json").json()
    glb = _ok(spec, "/simulations/{job_id}/workpiece/{pose}.glb")
    assert glb["model/gltf-binary"]["schema"] == {"type": "string", "format": "binary"}
    report = _ok(spec, "/simulations/{job_id}/report")
    assert report["text/csv"]["schema"] == {"type": "string"}
    assert report["application/json"]["schema"]["$ref"].endswith("/Report")
    from service.compensation import FILES as COMPENSATION
    from service.placement import FILES as PLACEMENT

    for path, files in (("/compensations/{job_id}/files/{name}", COMPENSATION),
                        ("/placement-searches/{job_id}/files/{name}", PLACEMENT)):
        content = _ok(spec, path)
        assert set(files.values()) <= set(content)
        assert content["image/png"]["schema"] == {"type": "string", "format": "binary"}


def test_report_poses_and_ranking_rows_are_typed(client):
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    assert schemas["Report"]["properties"]["poses"]["items"]["$ref"].endswith("/PoseSummary")
    pose = schemas["PoseSummary"]["properties"]
    for key in ("peak_force_n", "peak_deflection_m", "simulated_time_s", "in_tolerance", "worst_feature"):
        assert key in pose
    row = schemas["FeatureRow"]["properties"]
    assert {"deviation_mm", "in_tolerance", "worst_instance", "tolerance_mm"} <= set(row)
