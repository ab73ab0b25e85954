"""Generated hidden-effect records for the diagnosis tests (20 s, 1 kHz: 20k samples each)."""
from pathlib import Path

import pytest

from identify.axis_limits import load_axis_limits
from identify.trajectories import test_trajectory, universal_trajectory

ROBOT = Path(__file__).resolve().parents[2] / "data" / "robots" / "max100.toml"
DURATION = 20.0
NOISE = 0.02  # plant sensor noise [Nm] (PlantConfig default)
GENERATIONS = 15  # GA generations of the baseline in the fast tests


@pytest.fixture(scope="session")
def trajectories():
    limits = load_axis_limits(ROBOT, 1)
    return universal_trajectory(limits, duration=DURATION), test_trajectory(limits, duration=DURATION)


def _make_pair(trajectories, effect, magnitude, seed, extra=None):
    """(train, test) records with the hidden effect; ``extra(frame)`` may add a second effect."""
    from identify.plant import synthesize
    from identify.records import validate_frame

    recs = []
    for traj, s, name in ((trajectories[0], seed, "train"), (trajectories[1], seed + 500, "test")):
        frame = synthesize(traj.t, traj.q, traj.qd, traj.qdd, seed=s, effect=effect, magnitude=magnitude).frame
        if extra is not None:
            frame = extra(frame)
        recs.append(validate_frame(frame, f"{name}-{effect}-{s}"))
    return recs


@pytest.fixture(scope="session")
def case_files(tmp_path_factory, trajectories):
    """CSV train/test records with a hidden drift, for the CLI tests."""
    root = tmp_path_factory.mktemp("diag-cli")
    train, test = _make_pair(trajectories, "drift", 0.5, seed=7)
    paths = {}
    for rec, name in ((train, "train.csv"), (test, "test.csv")):
        rec.frame.to_csv(root / name, index=False)
        paths[name.split(".")[0]] = root / name
    return paths


@pytest.fixture(scope="session")
def make_pair(trajectories):
    """``make_pair(effect, magnitude, seed, extra=None) -> (train, test)`` records."""
    return lambda effect, magnitude, seed, extra=None: _make_pair(trajectories, effect, magnitude, seed, extra)
