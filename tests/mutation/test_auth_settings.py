"""API keys and service settings: wrong, missing and short keys refused, limits validated."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from fastapi import HTTPException

from identify.errors import InputError
from service.auth import HEADER, key_ok, require_key
from service.settings import DEV_API_KEY, ServiceSettings, load_settings

KEY = "right-key-0123"


pytestmark = pytest.mark.usefixtures("service_env_cleared")

def _request(settings):
    return SimpleNamespace(app=SimpleNamespace(state=SimpleNamespace(settings=settings)), state=SimpleNamespace())


def test_key_ok():
    keys = frozenset({KEY, "other-key-5678"})
    assert key_ok(KEY, keys) and key_ok("other-key-5678", keys)
    assert not key_ok("right-key-012", keys)
    assert not key_ok(KEY + "x", keys)
    assert not key_ok("", keys) and not key_ok(None, keys)
    assert not key_ok(KEY, frozenset())
    assert not key_ok("", frozenset({""}))  # an empty header never passes


def test_require_key_accepts_and_records_owner():
    s = load_settings(api_keys=f"{KEY}, second-key-000")
    req = _request(s)
    assert require_key(req, "second-key-000") == "second-key-000"
    assert req.state.api_key == "second-key-000"


@pytest.mark.parametrize("given", [None, "", "wrong-key-0123", KEY.upper()])
def test_require_key_refuses_with_401(given):
    req = _request(load_settings(api_keys=KEY))
    with pytest.raises(HTTPException) as e:
        require_key(req, given)
    assert e.value.status_code == 401
    assert e.value.headers == {"WWW-Authenticate": "X-API-Key"}
    assert HEADER == "X-API-Key" and "X-API-Key" in e.value.detail
    assert not hasattr(req.state, "api_key")


def test_dev_mode_key_only_without_configured_keys():
    s = load_settings(dev_mode=True)
    assert s.keys() == frozenset({DEV_API_KEY}) and DEV_API_KEY == "greybench-dev"
    assert load_settings(dev_mode=True, api_keys=KEY).keys() == frozenset({KEY})
    assert load_settings(api_keys=f" {KEY} ,, b-key-12345 ,").keys() == frozenset({KEY, "b-key-12345"})


def test_settings_refuse_missing_short_or_spaced_keys():
    with pytest.raises(InputError) as e:
        load_settings()
    assert "no API key" in e.value.message and e.value.source == "environment"
    with pytest.raises(InputError) as e:
        load_settings(api_keys="short7!")
    assert "8 characters" in e.value.message
    assert load_settings(api_keys="exactly8").keys() == frozenset({"exactly8"})
    with pytest.raises(InputError):
        load_settings(api_keys="has space-123")
    with pytest.raises(InputError):
        load_settings(api_keys="has\ttab-123")


def test_settings_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("GREYBENCH_API_KEYS", KEY)
    monkeypatch.setenv("GREYBENCH_WORKERS", "3")
    monkeypatch.setenv("GREYBENCH_QUEUE_SIZE", "5")
    monkeypatch.setenv("GREYBENCH_DATA_DIR", str(tmp_path))
    monkeypatch.setenv("RAY_ADDRESS", "  ")
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "sqlite:///x.db")
    s = load_settings()
    assert s.workers == 3 and s.capacity == 8
    assert s.db_path == tmp_path / "jobs.sqlite" and s.jobs_dir == tmp_path / "jobs"
    assert s.ray_address is None            # blank means no cluster
    assert s.mlflow_tracking_uri == "sqlite:///x.db"
    monkeypatch.setenv("RAY_ADDRESS", "local")
    assert load_settings().ray_address == "local"


def test_settings_defaults():
    s = load_settings(api_keys=KEY)
    assert (s.workers, s.queue_size, s.jobs_per_key, s.retry_after) == (2, 8, 4, 10)
    assert s.data_dir == Path("greybench-service") and s.cores is None and not s.dev_mode
    assert (s.max_program_lines, s.max_cut_seconds, s.max_job_memory_mb) == (200_000, 14_400.0, 4096.0)
    assert s.max_body_bytes == 2 * 1024 * 1024
    lim = s.cost_limits()
    assert (lim.max_lines, lim.max_cut_seconds, lim.max_memory_bytes) == (200_000, 14_400.0, 4096.0 * 1024 ** 2)
    lim = load_settings(api_keys=KEY, max_program_lines=10, max_cut_seconds=1.5, max_job_memory_mb=2.0).cost_limits()
    assert (lim.max_lines, lim.max_cut_seconds, lim.max_memory_bytes) == (10, 1.5, 2.0 * 1024 ** 2)


@pytest.mark.parametrize("field,bad,good", [("workers", 0, 1), ("workers", 65, 64), ("queue_size", -1, 0),
                                            ("queue_size", 10_001, 10_000), ("jobs_per_key", 0, 1),
                                            ("retry_after", 0, 1), ("retry_after", 3601, 3600), ("cores", 0, 1),
                                            ("max_program_lines", 9, 10), ("max_cut_seconds", 0.0, 1e-3),
                                            ("max_job_memory_mb", 0.0, 1e-3), ("max_body_bytes", 1023, 1024),
                                            ("max_cut_seconds", float("inf"), 1e7)])
def test_settings_bounds_name_the_variable(field, bad, good):
    with pytest.raises(InputError) as e:
        load_settings(api_keys=KEY, **{field: bad})
    assert e.value.field == "GREYBENCH_" + field.upper()
    assert e.value.message.startswith("invalid service settings: ")
    assert getattr(load_settings(api_keys=KEY, **{field: good}), field) == good


def test_settings_model_error_has_no_field():
    with pytest.raises(InputError) as e:
        load_settings(api_keys="")
    assert e.value.field is None
    assert isinstance(ServiceSettings(api_keys=KEY), ServiceSettings)
