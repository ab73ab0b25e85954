"""Loop friction (the compiled form the coupled loop evaluates) against each model's own ``predict``.

Every saved model type, fed the same motion sample by sample, must give the friction torque of its
own ``predict_friction`` within 1% of that model's torque RMS. The motion is a synthetic 4 s record
(1 kHz) whose acceleration column is the backward difference of its velocity, as the loop forms it;
the models are fitted with a few epochs (their accuracy is not the point, their form is).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from identify.axis_limits import AxisLimits
from identify.plant import PlantConfig, synthesize
from identify.records import validate_frame
from identify.trajectories import universal_trajectory
from simulate.robot.loop_friction import (FrictionKind, assemble, friction_series, joint_from_folder, new_state)

models = pytest.importorskip("identify.models")
LIMITS = AxisLimits(-3.2, 3.2, 2.1, 6.0, 60.0)


@pytest.fixture(scope="module")
def record():
    tr = universal_trajectory(LIMITS, duration=4.0)
    frame = synthesize(tr.t, tr.q, tr.qd, tr.qdd, config=replace(PlantConfig(), static_curve="hump"), seed=1).frame
    qd = frame["qd"].to_numpy()
    frame["qdd"] = np.concatenate([[0.0], np.diff(qd) / np.diff(frame["t"].to_numpy())])
    return validate_frame(frame, "loop-friction")


def _saved(cls, params, directory, **hyper):
    m = cls(**hyper)
    m.rigid_ = True
    m.params_ = dict(params, J=0.0, c=0.0)
    return m.save(directory)


LUGRE = dict(s0=2e4, s1=30.0, nu=1.5, fc=2.0, fs=3.0, vs=0.05, delta=1.5)


def _fitted(kind, rec, folder):
    if kind == "coulomb-viscous":
        return _saved(models.CoulombViscous, {"mu": 2.0, "nu": 1.5}, folder)
    if kind == "stribeck":
        return _saved(models.Stribeck, {k: LUGRE[k] for k in ("fc", "fs", "vs", "delta", "nu")}, folder)
    if kind == "lugre":
        return _saved(models.LuGre, LUGRE, folder)
    if kind == "lugre-extended":
        p = dict(LUGRE, load_ref=float(np.mean(np.abs(rec.tau_load))), temp_ref=float(np.mean(rec.temp)),
                 k_load=0.004, asym=0.2, ripple_sin=0.1, ripple_cos=-0.05, ripple_order=12.0, k_nu_temp=0.0,
                 k_dry_temp=0.0)
        return _saved(models.LuGreExtended, p, folder, causes=["load", "asymmetry", "position", "temperature"])
    est = {"greybox": lambda: models.GreyBoxLuGre(epochs=5),
           "residual": lambda: models.ResidualLuGre(epochs=20, population=8, generations=3),
           "lstm": lambda: models.LSTMFriction(epochs=2, batches=2, window=120, warmup=200)}[kind]()
    return est.fit(rec).save(folder)


@pytest.mark.parametrize("kind", ["coulomb-viscous", "stribeck", "lugre", "lugre-extended", "greybox", "residual",
                                  "lstm"])
def test_loop_friction_equals_the_models_predict(record, tmp_path, kind):
    folder = _fitted(kind, record, tmp_path / kind)
    own = models.load_model(folder).predict_friction(record)
    row = joint_from_folder(folder, sample_period=record.sample_time)
    assert row["kind"] == int({"coulomb-viscous": FrictionKind.COULOMB_VISCOUS, "stribeck": FrictionKind.STRIBECK,
                               "lugre": FrictionKind.LUGRE, "lugre-extended": FrictionKind.LUGRE_EXTENDED,
                               "greybox": FrictionKind.GREYBOX, "residual": FrictionKind.RESIDUAL,
                               "lstm": FrictionKind.LSTM}[kind])
    p = assemble([None, None, row, None, None, None])   # any joint slot: the third here
    dt = np.concatenate([[0.0], np.diff(record.t)])
    loop = friction_series(p, 2, new_state(p), record.qd.astype(float), record.q.astype(float),
                           record.tau_load.astype(float), dt)
    rms = float(np.sqrt(np.mean(own ** 2)))
    err = float(np.sqrt(np.mean((loop - own) ** 2)))
    assert rms > 0.5   # a real torque, not a degenerate model
    assert err <= 0.01 * rms, f"{kind}: loop vs predict {err:.3g} Nm RMS, model {rms:.3g} Nm RMS"
    # the same arithmetic: round-off; the LSTM's torch weights are float32 (the loop runs float64).
    # Run continuously instead of in the model's windows, the LSTM would be 1.2e-3 of its RMS off.
    assert err <= (1e-4 if kind == "lstm" else 1e-6) * rms
