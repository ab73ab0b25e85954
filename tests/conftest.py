"""Project-wide test settings: nothing a test does may write into the working tree.

``make test`` runs the suite on every core with pytest-xdist (``-n auto --dist loadgroup``): each
worker process has its own temporary folders (``tmp_path_factory``), MLflow store, ports
(``free_port``) and environment, and its share of the cores for its thread pools.
"""
import os

import pytest

# An xdist worker sizes its torch/numba/BLAS thread pools to its share of the cores before any of
# them loads (two workers with a thread per core each would oversubscribe the machine twice over).
if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
    from identify.resources import configure_threads, plan

    configure_threads(plan(int(os.environ["PYTEST_XDIST_WORKER_COUNT"])).threads)

try:  # one intra-op thread: the suite's fits are small, and two threads thrash on a shared 2-core machine
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover
    pass

#: Tests that must not overlap in time, by the xdist group they share (one worker runs a group).
#: Ray: each test starts a local Ray instance sized to one core; two at once would share the machine's.
SERIAL_GROUPS = {"ray": ("tests/placement/test_ray.py", "tests/service/test_ray.py")}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under ``--dist loadgroup``: a module whose tests share a module-scoped fixture (a served
    process, a browser, a fitted model) stays on one worker, so the fixture is made once; the
    ``SERIAL_GROUPS`` stay on one worker each. Every other test goes to whichever worker is free.
    Runs before xdist's own hook, which turns the groups into node ids."""
    if not getattr(config.option, "loadgroup", False):  # set in xdist's workers under --dist loadgroup
        return
    serial = {path: group for group, paths in SERIAL_GROUPS.items() for path in paths}
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        module = item.nodeid.split("::", 1)[0]
        if module in serial:
            item.add_marker(pytest.mark.xdist_group(serial[module]))
        elif any(defs[-1].scope in ("module", "package") for defs in _fixture_defs(item)):
            item.add_marker(pytest.mark.xdist_group(module))


def _fixture_defs(item) -> list:
    info = getattr(item, "_fixtureinfo", None)  # doctest items have none
    return [] if info is None else [defs for defs in info.name2fixturedefs.values() if defs]


@pytest.fixture(autouse=True, scope="session")
def _isolated_tracking(tmp_path_factory):
    """Point MLflow at a throwaway SQLite store for the whole session."""
    root = tmp_path_factory.mktemp("mlflow")
    old = os.environ.get("MLFLOW_TRACKING_URI")
    os.environ["MLFLOW_TRACKING_URI"] = f"sqlite:///{root}/mlruns.db"
    os.environ.setdefault("MPLBACKEND", "Agg")
    yield
    if old is None:
        os.environ.pop("MLFLOW_TRACKING_URI", None)
    else:
        os.environ["MLFLOW_TRACKING_URI"] = old
