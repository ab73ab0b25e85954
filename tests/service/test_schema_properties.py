"""Property-based API tests from the OpenAPI schema (schemathesis): no input gives a 5xx.

Bounded: a few examples per operation, against a real server on loopback.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings

from .conftest import KEY


def _schema_document() -> dict:
    from service.app import create_app
    from service.settings import load_settings

    with tempfile.TemporaryDirectory() as d:
        app = create_app(load_settings(api_keys=KEY, data_dir=Path(d) / "data"))
        doc = app.openapi()
        app.state.manager.shutdown()
    return doc


schema = schemathesis.openapi.from_dict(_schema_document())


@pytest.fixture(scope="module")
def base_url(shared_server):
    return shared_server.url


@schema.parametrize()
@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
def test_no_server_errors(case, base_url):
    response = case.call(base_url=base_url, headers={"X-API-Key": KEY}, timeout=60)
    assert response.status_code < 500, (case.method, case.path, case.body, response.status_code, response.text[:500])


@schema.parametrize()
@settings(max_examples=3, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
def test_without_a_key_only_health_answers(case, base_url):
    response = case.call(base_url=base_url, headers={"X-API-Key": "not-a-key"}, timeout=60)
    if case.path == "/health" and case.method.upper() == "GET":
        assert response.status_code == 200
    elif case.method.upper() == "OPTIONS":  # the allowed methods, public in /openapi.json as well
        allow = {k.lower(): v for k, v in response.headers.items()}["allow"]
        assert response.status_code == 204 and "OPTIONS" in str(allow)
    else:
        assert response.status_code in (401, 404, 405, 413, 422), (case.method, case.path, response.status_code)
