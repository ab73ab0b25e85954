"""Synthetic axis records with known parameters (the plant's truth), shared by the identify tests."""
from pathlib import Path

import pytest

from identify.axis_limits import load_axis_limits
from identify.plant import PlantConfig, synthesize
from identify.records import validate_frame
from identify.trajectories import test_trajectory, universal_trajectory

ROBOT = Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml"


@pytest.fixture(scope="session")
def limits():
    return load_axis_limits(ROBOT, 1)


@pytest.fixture(scope="session")
def plant():
    return PlantConfig()


@pytest.fixture(scope="session")
def ut(limits):
    return universal_trajectory(limits)


@pytest.fixture(scope="session")
def ut_test(limits):
    return test_trajectory(limits)


@pytest.fixture(scope="session")
def train_record(ut, plant):
    return validate_frame(synthesize(ut.t, ut.q, ut.qd, ut.qdd, config=plant, seed=1).frame, "synth-train")


@pytest.fixture(scope="session")
def test_record(ut_test, plant):
    return validate_frame(synthesize(ut_test.t, ut_test.q, ut_test.qd, ut_test.qdd, config=plant, seed=2).frame,
                          "synth-test")


@pytest.fixture(scope="session")
def fitted_lugre(train_record):
    from identify.models import LuGre

    return LuGre(seed=0).fit(train_record)
