"""Service settings: every documented limit at both edges, the environment names and the key rules.

Complements tests/mutation/test_auth_settings.py: the bounds live in the field declarations, which a
changed comparison or constant would move by one step; each edge is checked just inside and just outside.
"""
from __future__ import annotations

import math

import pytest

from identify.errors import InputError
from service.settings import DEV_API_KEY, load_settings

KEY = "right-key-0123"


pytestmark = pytest.mark.usefixtures("service_env_cleared")

# (field, refused just outside, accepted at the edge); the module docstring documents each range
EDGES = [
    ("workers", 0, 1), ("workers", 65, 64),
    ("queue_size", -1, 0), ("queue_size", 10_001, 10_000),
    ("jobs_per_key", 0, 1), ("jobs_per_key", 10_001, 10_000),
    ("retry_after", 0, 1), ("retry_after", 3601, 3600),
    ("cores", 0, 1), ("cores", 4097, 4096),
    ("max_program_lines", 9, 10), ("max_program_lines", 100_000_001, 100_000_000),
    ("max_cut_seconds", 0.0, 1e-9), ("max_cut_seconds", 1e7 * (1 + 1e-12), 1e7),
    ("max_job_memory_mb", 0.0, 1e-9), ("max_job_memory_mb", 1e7 * (1 + 1e-12), 1e7),
    ("max_body_bytes", 1023, 1024), ("max_body_bytes", 1024 ** 3 + 1, 1024 ** 3),
    ("view_secret", "s" * 15, "s" * 16),
]


@pytest.mark.parametrize("field,bad,good", EDGES)
def test_each_limit_refused_just_outside_and_accepted_at_its_edge(field, bad, good):
    with pytest.raises(InputError) as e:
        load_settings(api_keys=KEY, **{field: bad})
    assert e.value.field == "GREYBENCH_" + field.upper() and e.value.source == "environment"
    assert getattr(load_settings(api_keys=KEY, **{field: good}), field) == good


@pytest.mark.parametrize("field", ["max_cut_seconds", "max_job_memory_mb"])
@pytest.mark.parametrize("bad", [math.inf, -math.inf, math.nan])
def test_non_finite_time_and_memory_limits_are_refused(field, bad):
    with pytest.raises(InputError) as e:
        load_settings(api_keys=KEY, **{field: bad})
    assert e.value.field == "GREYBENCH_" + field.upper()


def test_unset_optional_settings_are_none_and_dev_mode_off():
    s = load_settings(api_keys=KEY)
    assert s.view_secret is None and s.ray_address is None and s.mlflow_tracking_uri is None
    assert s.dev_mode is False and s.capacity == 2 + 8
    assert load_settings(api_keys=KEY, workers=5, queue_size=0).capacity == 5


def test_environment_names_aliases_and_unknown_variables(monkeypatch, tmp_path):
    monkeypatch.setenv("GREYBENCH_API_KEYS", KEY)
    monkeypatch.setenv("GREYBENCH_JOBS_PER_KEY", "7")
    monkeypatch.setenv("GREYBENCH_RETRY_AFTER", "30")
    monkeypatch.setenv("GREYBENCH_CORES", "3")
    monkeypatch.setenv("GREYBENCH_MAX_PROGRAM_LINES", "1234")
    monkeypatch.setenv("GREYBENCH_MAX_CUT_SECONDS", "60.5")
    monkeypatch.setenv("GREYBENCH_MAX_JOB_MEMORY_MB", "512")
    monkeypatch.setenv("GREYBENCH_MAX_BODY_BYTES", "4096")
    monkeypatch.setenv("GREYBENCH_VIEW_SECRET", "0123456789abcdef")
    monkeypatch.setenv("GREYBENCH_SOMETHING_ELSE", "ignored")      # unknown variables are ignored
    monkeypatch.setenv("GREYBENCH_RAY_ADDRESS", "ray://head:10001")
    monkeypatch.setenv("GREYBENCH_MLFLOW_TRACKING_URI", "sqlite:///m.db")
    s = load_settings()
    assert (s.jobs_per_key, s.retry_after, s.cores, s.max_program_lines) == (7, 30, 3, 1234)
    assert (s.max_cut_seconds, s.max_job_memory_mb, s.max_body_bytes) == (60.5, 512.0, 4096)
    assert s.view_secret == "0123456789abcdef"
    assert s.ray_address == "ray://head:10001" and s.mlflow_tracking_uri == "sqlite:///m.db"
    # the tools' own names come first
    monkeypatch.setenv("RAY_ADDRESS", "local")
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://tracking:5000")
    s = load_settings()
    assert s.ray_address == "local" and s.mlflow_tracking_uri == "http://tracking:5000"
    lim = s.cost_limits()
    assert (lim.max_lines, lim.max_cut_seconds, lim.max_memory_bytes) == (1234, 60.5, 512 * 1048576)
    monkeypatch.setenv("GREYBENCH_DEV_MODE", "1")
    assert load_settings().dev_mode is True


def test_keys_rules():
    # at least 8 characters, no white space anywhere in a key; blanks between commas are skipped
    assert load_settings(api_keys="abcdefgh,ABCDEFGHI").keys() == frozenset({"abcdefgh", "ABCDEFGHI"})
    assert load_settings(api_keys="abcdefgh\n").keys() == frozenset({"abcdefgh"})   # surrounding blanks trimmed
    for bad in ("abcdefgh,abcdefg", "abcd efgh", "abcdefgh,a\u00a0bcdefgh"):
        with pytest.raises(InputError) as e:
            load_settings(api_keys=bad)
        assert e.value.field is None and "8 characters and no spaces" in e.value.message
    # dev mode alone accepts only the documented key; a configured key replaces it
    assert load_settings(dev_mode=True, api_keys=" , ").keys() == frozenset({DEV_API_KEY})
    assert load_settings(dev_mode=True, api_keys=KEY).keys() == frozenset({KEY})
    assert load_settings(api_keys=KEY).keys() == frozenset({KEY})
    with pytest.raises(InputError) as e:
        load_settings(api_keys=" ,, ")
    assert "no API key configured" in e.value.message and "GREYBENCH_DEV_MODE=1" in e.value.message


def test_a_blank_ray_address_means_no_cluster_but_a_given_one_is_kept_as_given():
    assert load_settings(api_keys=KEY, ray_address=" \t").ray_address is None
    assert load_settings(api_keys=KEY, ray_address="").ray_address is None
    assert load_settings(api_keys=KEY, ray_address=" local ").ray_address == " local "


def test_paths_follow_the_data_dir(tmp_path):
    s = load_settings(api_keys=KEY, data_dir=tmp_path / "svc")
    assert s.db_path == tmp_path / "svc" / "jobs.sqlite" and s.jobs_dir == tmp_path / "svc" / "jobs"
    assert s.db_path.parent == s.jobs_dir.parent == s.data_dir


def test_error_message_is_pydantic_first_message_with_the_variable():
    with pytest.raises(InputError) as e:
        load_settings(api_keys=KEY, workers="many")
    assert e.value.field == "GREYBENCH_WORKERS"
    assert e.value.message.startswith("invalid service settings: ") and "integer" in e.value.message
