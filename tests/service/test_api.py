"""Routes in process (TestClient): keys, bad input -> 4xx naming the place, 404s, 413, 429, paths."""
from __future__ import annotations

import numpy as np
import pytest

from .conftest import HEADERS

BAD_GCODE = "G21 G90 G17\nG0 X0 Y0 Z5\nG1 X10 Y0 Z0 F300\nG1 X10 Y10 Q\n"


def test_health_needs_no_key_and_reports_the_queue(client):
    r = client.get("/health")
    assert r.status_code == 200
    body = r.json()
    assert body["status"] == "ok" and body["queue"] == {"active": 0, "capacity": 1, "workers": 1}
    assert body["backend"] == "local" and body["dev_mode"] is False


@pytest.mark.parametrize("headers", [{}, {"X-API-Key": "wrong-key-000"}, {"X-API-Key": ""}])
def test_every_other_route_needs_a_valid_key(client, headers):
    for method, url in [("get", "/models"), ("post", "/simulations"), ("get", "/simulations/" + "0" * 32),
                        ("post", "/friction/predict"), ("post", "/diagnose"), ("post", "/explain"),
                        ("get", "/jobs/" + "0" * 32)]:
        r = client.request(method.upper(), url, headers=headers, json={})
        assert r.status_code == 401, (method, url, r.status_code)
        assert "X-API-Key" in r.json()["detail"]


def test_invalid_gcode_is_422_naming_the_program_line(client):
    r = client.post("/simulations", headers=HEADERS, json={"gcode": BAD_GCODE, "pose_set": "iso160"})
    assert r.status_code == 422
    detail = r.json()["detail"]
    assert detail["source"] == "gcode" and detail["line"] == 4
    assert "Q" in detail["message"] or "word" in detail["message"].lower()


def test_schema_errors_are_422(client):
    for body in [{}, {"program": "iso160"}, {"program": "iso160", "gcode": "G0 X0", "pose_set": "iso160"},
                 {"program": "iso160", "pose_set": "iso160", "options": {"spacing_mm": -1}},
                 {"program": "iso160", "poses": [{"name": "a", "xyz": [0, 0], "rpy": [0, 0, 0]}]},
                 {"program": "iso160", "pose_set": "iso160", "friction": [{"axis": 7}]}]:
        r = client.post("/simulations", headers=HEADERS, json=body)
        assert r.status_code == 422, body
    r = client.post("/simulations", headers={**HEADERS, "Content-Type": "application/json"}, content=b"{not json")
    assert r.status_code == 422


def test_select_needs_a_pose_set_and_inline_gcode_a_stock(client):
    body = {"program": "iso160", "poses": [{"name": "far", "xyz": [9.0, 0, 0], "rpy": [0, 0, 0]}]}
    r = client.post("/simulations", headers=HEADERS, json={**body, "select": ["x"]})
    assert r.status_code == 422  # 'select' picks poses of a pose_set
    r = client.post("/simulations", headers=HEADERS, json={"gcode": "G21 G90\nS12000 M3\nG0 X0 Y0 Z5\nG1 X10 F1000\n",
                                                           "pose_set": "iso160"})  # valid: only the stock missing
    assert r.status_code == 422 and r.json()["detail"]["field"] == "stock"


def test_unknown_names_and_model_references_are_404(client):
    cases = [{"program": "nope", "pose_set": "iso160"}, {"program": "iso160", "pose_set": "nope"},
             {"program": "iso160", "pose_set": "iso160", "robot": "nope"},
             {"program": "iso160", "pose_set": "iso160", "friction": [{"axis": 3, "model": "champion"}]},
             {"program": "iso160", "pose_set": "iso160", "friction": [{"axis": 2, "model": "17"}]}]
    for body in cases:
        r = client.post("/simulations", headers=HEADERS, json=body)
        assert r.status_code == 404, (body, r.json())
    assert "max100-axis3-friction" in client.post("/simulations", headers=HEADERS, json=cases[3]).json()["detail"]
    r = client.post("/simulations", headers=HEADERS, json={"program": "iso160", "pose_set": "iso160",
                                                            "select": ["nope"]})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "select"
    assert client.get("/simulations/" + "a" * 32, headers=HEADERS).status_code == 404
    assert client.get("/simulations/not-a-job", headers=HEADERS).status_code in (404, 422)


@pytest.mark.parametrize("url", [
    "/simulations/%2e%2e%2f%2e%2e%2fjobs.sqlite/ranking",
    "/simulations/" + "a" * 32 + "/workpiece/..%2F..%2Fjobs.sqlite.glb",
    "/simulations/" + "a" * 32 + "/workpiece/%2e%2e.glb",
    "/simulations/../../etc/passwd",
    "/simulations/" + "a" * 32 + "/workpiece/..%2F..%2F..%2Fdata%2Frobots%2Fmax100.glb",
])
def test_path_parameters_cannot_leave_the_data_folders(client, url):
    r = client.get(url, headers=HEADERS)
    assert r.status_code in (404, 422), (url, r.status_code)


@pytest.mark.parametrize("name", ["../robots/max100", "..", ".hidden", "a/b", "iso160\x00", "x" * 65])
def test_named_files_cannot_leave_the_data_folders(client, name):
    for body in [{"program": name, "pose_set": "iso160"}, {"program": "iso160", "pose_set": name},
                 {"program": "iso160", "pose_set": "iso160", "robot": name}]:
        r = client.post("/simulations", headers=HEADERS, json=body)
        assert r.status_code in (404, 422), (body, r.status_code)


def test_oversized_bodies_are_413(client, settings):
    big = b"{" + b" " * (settings.max_body_bytes + 10) + b"}"
    r = client.post("/simulations", headers={**HEADERS, "Content-Type": "application/json"}, content=big)
    assert r.status_code == 413 and str(settings.max_body_bytes) in r.json()["detail"]

    def chunks():  # streamed, no Content-Length: counted while read
        for _ in range(settings.max_body_bytes // 4096 + 4):
            yield b" " * 4096

    r = client.post("/friction/predict", headers={**HEADERS, "Content-Type": "application/json"}, content=chunks())
    assert r.status_code == 413


def test_full_queue_is_429_with_retry_after(client, settings):
    body = {"program": "iso160", "pose_set": "iso160", "select": ["near"]}
    first = client.post("/simulations", headers=HEADERS, json=body)
    assert first.status_code == 202 and first.headers["Location"] == f"/simulations/{first.json()['id']}"
    second = client.post("/simulations", headers=HEADERS, json=body)
    assert second.status_code == 429
    assert second.headers["Retry-After"] == str(settings.retry_after)
    # cancelling the first frees the slot once its future is done
    r = client.delete(f"/simulations/{first.json()['id']}", headers=HEADERS)
    assert r.status_code == 200 and r.json()["state"] == "cancelled"


def test_results_of_an_unfinished_job_are_409(client):
    body = {"program": "iso160", "pose_set": "iso160", "select": ["near"]}
    job = client.post("/simulations", headers=HEADERS, json=body).json()["id"]
    for suffix in ("/ranking", "/report", "/report?format=csv", "/workpiece/near.glb"):
        r = client.get(f"/simulations/{job}{suffix}", headers=HEADERS)
        assert r.status_code == 409, suffix
    client.delete(f"/simulations/{job}", headers=HEADERS)


def test_models_lists_registered_versions_with_aliases_and_metrics(client, registered_model):
    _, _, run_id = registered_model
    models = {m["name"]: m for m in client.get("/models", headers=HEADERS).json()["models"]}
    m = models["max100-axis1-friction"]
    assert m["aliases"] == {"champion": 1}
    v = m["versions"][0]
    assert v["version"] == 1 and v["aliases"] == ["champion"] and v["run_id"] == run_id
    assert v["metrics"]["test_rmse"] == pytest.approx(0.0123)


def test_friction_predict_matches_the_registered_model(client, registered_model):
    model, rec, _ = registered_model
    n = 400
    body = {"model": {"robot": "max100", "axis": 1, "ref": "champion"}, "t": rec.t[:n].tolist(),
            "q": rec.q[:n].tolist(), "qd": rec.qd[:n].tolist(), "qdd": rec.qdd[:n].tolist()}
    r = client.post("/friction/predict", headers=HEADERS, json=body)
    assert r.status_code == 200, r.json()
    out = r.json()
    assert out["model"]["version"] == 1 and out["model"]["uri"] == "models:/max100-axis1-friction/1"
    from identify.records import record_from_arrays
    sub = record_from_arrays(rec.t[:n], rec.q[:n], np.zeros(n), qd=rec.qd[:n], qdd=rec.qdd[:n])
    np.testing.assert_allclose(out["tau"], model.predict(sub), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(out["tau_friction"], model.predict_friction(sub), rtol=1e-12, atol=1e-12)
    # the same by version number
    body["model"]["ref"] = "1"
    assert client.post("/friction/predict", headers=HEADERS, json=body).json()["tau"] == out["tau"]


def test_friction_predict_bad_input(client, registered_model):
    _, rec, _ = registered_model
    base = {"model": {"axis": 1}, "t": rec.t[:300].tolist(), "q": rec.q[:300].tolist()}
    r = client.post("/friction/predict", headers=HEADERS, json={**base, "model": {"axis": 1, "ref": "nobody"}})
    assert r.status_code == 404 and "nobody" in r.json()["detail"]
    r = client.post("/friction/predict", headers=HEADERS, json={**base, "model": {"axis": 4}})
    assert r.status_code == 404 and "max100-axis4-friction" in r.json()["detail"]
    r = client.post("/friction/predict", headers=HEADERS, json={**base, "qd": [0.0] * 10})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "qd"
    t = rec.t[:300].copy()
    t[100] = t[99]
    r = client.post("/friction/predict", headers=HEADERS, json={**base, "t": t.tolist()})
    assert r.status_code == 422
    d = r.json()["detail"]
    assert d["field"] == "t" and d["row"] == 100 and d["source"] == "request"
    r = client.post("/friction/predict", headers=HEADERS, json={**base, "q": (rec.q[:300] * 100).tolist()})
    assert r.status_code == 422 and r.json()["detail"]["field"] == "q"


def test_diagnose_bad_records_are_422_naming_file_row_and_column(client):
    good = "t,q,tau\n" + "\n".join(f"{k * 1e-3},{0.1 * np.sin(k * 1e-2)},{0.5}" for k in range(300))
    r = client.post("/diagnose", headers=HEADERS, json={"train_csv": "t,q\n0,1\n", "test_csv": good})
    assert r.status_code == 422
    d = r.json()["detail"]
    assert d["source"] == "train.csv" and d["field"] == "tau"
    bad = good.replace("\n0.1,", "\n0.1x,", 1).replace(f"\n{100 * 1e-3},", "\nabc,", 1)
    r = client.post("/diagnose", headers=HEADERS, json={"train_csv": good, "test_csv": bad})
    assert r.status_code == 422
    d = r.json()["detail"]
    assert d["source"] == "test.csv" and d["field"] == "t" and d["row"] == 100


def test_explain_bad_scan_is_422(client):
    r = client.post("/explain", headers=HEADERS, json={"scan_csv": "feature,x,y\ncircle,0,0\n", "program": "iso160",
                                                       "pose_set": "iso160", "pose": "near"})
    assert r.status_code == 422 and r.json()["detail"] == {"message": "missing required column 'z'",
                                                           "source": "scan.csv", "field": "z"}
    r = client.post("/explain", headers=HEADERS, json={"scan_csv": "feature,x,y,z\ncircle,0,0,0\n",
                                                       "gcode": BAD_GCODE, "pose_set": "iso160", "pose": "near"})
    assert r.status_code == 422 and r.json()["detail"]["line"] == 4


def test_fetch_writes_the_model_folder_whole_and_leaves_nothing_else(registered_model, tmp_path):
    """registry.fetch: the saved-model folder alone (params.json at its top), an older copy replaced, no
    temporary left beside it; a version without a saved model is refused and the old copy kept."""
    import mlflow

    from identify.models import load_model
    from service import registry

    model, rec, _ = registered_model
    pinned = registry.resolve("max100-axis1-friction", "champion")
    into = tmp_path / "models" / "axis1"
    into.mkdir(parents=True)
    (into / "stale.txt").write_text("an older download")
    assert registry.fetch(pinned, into) == into
    assert (into / "params.json").is_file() and not (into / "stale.txt").exists()
    assert sorted(p.name for p in into.parent.iterdir()) == ["axis1"]
    got = load_model(into).predict(rec)
    assert np.allclose(got, model.predict(rec))
    # a registered version whose run holds no saved friction model (a name of its own: the other tests
    # list max100-axis1-friction's versions)
    client = mlflow.MlflowClient()
    with mlflow.start_run() as run:
        mlflow.log_text("not a model", "model/readme.txt")
    client.create_registered_model("test-no-model")
    mv = client.create_model_version("test-no-model", f"runs:/{run.info.run_id}/model", run_id=run.info.run_id)
    empty = registry.resolve("test-no-model", str(mv.version))
    with pytest.raises(registry.ModelNotFound, match="no saved friction model"):
        registry.fetch(empty, into)
    assert (into / "params.json").is_file() and sorted(p.name for p in into.parent.iterdir()) == ["axis1"]
