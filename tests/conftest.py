"""Project-wide test settings: nothing a test does may write into the working tree.

``make test`` runs the suite on every core with pytest-xdist (``-n auto --dist loadgroup``): each
worker process has its own temporary folders (``tmp_path_factory``), MLflow store, ports
(``free_port``) and environment, and its share of the cores for its thread pools.
"""
import os
from pathlib import Path

import pytest

pytest_plugins = ["pytester"]  # tests/test_xdist_groups.py runs the suite's parallel set-up on small modules

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
#: Costly session fixtures used in several folders, by the xdist group of the tests that use them:
#: on one worker the fixture is made once.
SHARED_FIXTURES = {"few_epoch_models": "few-epoch-models"}
#: Few-epoch hyper-parameters of the learned friction models: quick fits for tests that a model acts in
#: the machining loop (its accuracy is tested in tests/learned).
FEW_EPOCHS = {"greybox": dict(epochs=5), "residual": dict(epochs=10, population=8, generations=3),
              "lstm": dict(epochs=2, batches=2)}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Under ``--dist loadgroup``: the ``SERIAL_GROUPS`` and the users of each of the ``SHARED_FIXTURES``
    stay on one worker each, and so does a module whose tests share a module-scoped fixture (a served
    process, a browser, a fitted model), so the fixture is made once. Every other test goes to whichever
    worker is free. Runs before xdist's own hook, which turns the groups into node ids."""
    if not getattr(config.option, "loadgroup", False):  # set in xdist's workers under --dist loadgroup
        return
    serial = {path: group for group, paths in SERIAL_GROUPS.items() for path in paths}
    for item in items:
        if item.get_closest_marker("xdist_group") is not None:
            continue
        module = item.nodeid.split("::", 1)[0]
        shared = [g for name, g in SHARED_FIXTURES.items() if name in getattr(item, "fixturenames", ())]
        if module in serial:
            item.add_marker(pytest.mark.xdist_group(serial[module]))
        elif shared:
            item.add_marker(pytest.mark.xdist_group(shared[0]))
        elif any(defs[-1].scope in ("module", "package") for defs in _fixture_defs(item)):
            item.add_marker(pytest.mark.xdist_group(module))


def _fixture_defs(item) -> list:
    """The item's fixture definitions, without those named ``_...``: set-up of the environment, cheap."""
    info = getattr(item, "_fixtureinfo", None)  # doctest items have none
    return [] if info is None else [defs for name, defs in info.name2fixturedefs.items()
                                    if defs and not name.startswith("_")]


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    """xdist (controller): each worker gets this process's COLUMNS and LINES (a worker starts with 80 and 24
    of its own, which rich would take as a fixed width and cut the tables the CLI writes to a pipe)."""
    node.workerinput["terminal_env"] = {k: os.environ.get(k) for k in ("COLUMNS", "LINES")}


def pytest_configure(config):
    for key, value in getattr(config, "workerinput", {}).get("terminal_env", {}).items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value


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


@pytest.fixture(scope="session")
def few_epoch_models(tmp_path_factory):
    """``few_epoch_models(kind, folder)`` -> ``folder``: a copy of the saved grey-box, residual or LSTM model
    (``FEW_EPOCHS``) fitted on a 4 s synthetic axis-1 record whose static curve is not of the Stribeck form
    (the plant's "hump"); each kind is fitted once per session, on first use."""
    pytest.importorskip("torch")
    import shutil
    from dataclasses import replace

    from identify.axis_limits import AxisLimits
    from identify.models import make_model
    from identify.plant import PlantConfig, synthesize
    from identify.records import validate_frame
    from identify.trajectories import universal_trajectory

    root = tmp_path_factory.mktemp("few-epoch-models")
    saved: dict = {}

    def record():
        if "record" not in saved:
            tr = universal_trajectory(AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0), duration=4.0)
            frame = synthesize(tr.t, tr.q, tr.qd, tr.qdd, config=replace(PlantConfig(), static_curve="hump"),
                               seed=1).frame
            saved["record"] = validate_frame(frame, "few-epoch-record")
        return saved["record"]

    def copy(kind: str, folder):
        if kind not in saved:
            saved[kind] = make_model(kind, **FEW_EPOCHS[kind]).fit(record()).save(root / kind)
        return shutil.copytree(saved[kind], folder)

    return copy


#: The drive model's closed-form test robot: joint-side friction, a linear gear beyond its play
#: (``tests/data/max100_joint_friction.toml``, its header says why).
JOINT_FRICTION_ROBOT = Path(__file__).resolve().parent / "data" / "max100_joint_friction.toml"


@pytest.fixture(scope="session")
def joint_friction_robot_path():
    return JOINT_FRICTION_ROBOT


@pytest.fixture(scope="session")
def joint_friction_robot(joint_friction_robot_path):
    from simulate.robot.model import load_robot

    return load_robot(joint_friction_robot_path)
