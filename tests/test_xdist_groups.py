"""make test's parallel run (pytest-xdist, two workers, --dist loadgroup) with this suite's conftest: a
module-scoped fixture is made once and its module's tests run on one worker, the Ray tests share a worker,
the users of a shared session fixture share one, and the other tests are still spread over the workers."""
from __future__ import annotations

from pathlib import Path

import pytest

CONFTEST = Path(__file__).with_name("conftest.py")

#: Each test records "<kind> <worker>" in one file per test; the module fixture one line per creation.
RECORD = """
import os, time
from pathlib import Path

OUT = Path({out!r})


def record(kind):
    time.sleep(0.1)  # long enough that both workers are busy
    (OUT / f"{{kind}}-{{os.urandom(6).hex()}}").write_text(os.environ["PYTEST_XDIST_WORKER"])
"""

MODULE_FIXTURE = RECORD + """
import pytest


@pytest.fixture(scope="module")
def served():
    record("made")


@pytest.mark.parametrize("i", range(4))
def test_uses_it(served, i):
    record("module")


@pytest.mark.parametrize("i", range(4))
def test_does_not(i):
    record("free")
"""


def _worker_sets(out: Path) -> dict[str, list[str]]:
    seen: dict[str, list[str]] = {}
    for f in out.iterdir():
        seen.setdefault(f.name.split("-")[0], []).append(f.read_text())
    return seen


def test_groups_under_two_workers(pytester, monkeypatch):
    pytest.importorskip("xdist")
    for var in ("PYTEST_XDIST_WORKER", "PYTEST_XDIST_WORKER_COUNT", "PYTEST_ADDOPTS"):  # when make test runs it
        monkeypatch.delenv(var, raising=False)
    out = pytester.mkdir("out")
    pytester.makeconftest(CONFTEST.read_text())
    pytester.makeini("[pytest]\naddopts = --import-mode=importlib\n")  # same-named modules, as in the suite
    ray = RECORD.format(out=str(out)) + "\n\ndef test_ray():\n    record('ray')\n"
    shared = RECORD.format(out=str(out)) + "\n\ndef test_shared(few_epoch_models):\n    record('shared')\n"
    free = RECORD.format(out=str(out)) + "".join(f"\n\ndef test_free_{i}():\n    record('free')\n" for i in range(8))
    modules = {"tests/placement/test_ray.py": ray, "tests/service/test_ray.py": ray, "tests/a/test_shared.py": shared,
               "tests/b/test_shared.py": shared, "tests/c/test_module.py": MODULE_FIXTURE.format(out=str(out)),
               "tests/d/test_free.py": free}
    for path, text in modules.items():
        (pytester.path / path).parent.mkdir(parents=True, exist_ok=True)
        (pytester.path / path).write_text(text)
    # the session fixture is only asked for: replace its body (fitting models) by nothing
    (pytester.path / "tests" / "conftest.py").write_text(
        "import pytest\n\n\n@pytest.fixture(scope='session')\ndef few_epoch_models():\n    return None\n")
    res = pytester.runpytest_subprocess("-n", "2", "--dist", "loadgroup", "-p", "no:cacheprovider", "tests")
    res.assert_outcomes(passed=20)
    seen = _worker_sets(out)
    assert len(seen["made"]) == 1, seen              # the module fixture: made once
    assert set(seen["module"]) == set(seen["made"])  # on the worker that made it
    assert len(set(seen["ray"])) == 1 and len(seen["ray"]) == 2, seen
    assert len(set(seen["shared"])) == 1 and len(seen["shared"]) == 2, seen
    assert set(seen["free"]) == {"gw0", "gw1"}, seen  # ungrouped tests: both workers
