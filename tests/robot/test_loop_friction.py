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
from simulate.robot.loop_friction import FrictionKind, assemble, friction_series, joint_from_folder, new_state

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


def test_static_curve_is_the_held_velocity_steady_state_and_scales():
    """static_friction (the level the NC's feed-forward reaches at a held speed) equals each form's
    friction after a long held velocity (closed forms for coulomb-viscous and Stribeck, the relaxed
    bristles for LuGre and the direction asymmetry of lugre-extended); scale_levels doubles it minus
    the viscous part; an LSTM has no level to scale."""
    from simulate.robot import loop_friction as lf

    rows = []
    for kind in (lf.FrictionKind.COULOMB_VISCOUS, lf.FrictionKind.STRIBECK, lf.FrictionKind.LUGRE,
                 lf.FrictionKind.LUGRE_EXTENDED):
        row = lf._empty()
        row["kind"] = int(kind)
        sc = row["scal"]
        sc[[lf.FC, lf.FS, lf.VS, lf.DELTA, lf.S0, lf.S1, lf.NU, lf.MU]] = [30.0, 45.0, 0.05, 2.0, 1e5, 300.0, 8.0, 25.0]
        if kind is lf.FrictionKind.LUGRE_EXTENDED:
            sc[lf.ASYM], sc[lf.EXT_FLAGS] = 0.2, float(lf.EXT_ASYMMETRY)
        rows.append(row)
    p = lf.assemble(rows + [None, None])
    n = 4000
    for v in (0.02, -0.3):
        for j in range(4):
            st = lf.new_state(p)
            out = lf.friction_series(p, j, st, np.full(n, v), np.zeros(n), np.zeros(n), np.full(n, 1e-3))
            assert out[-1] == pytest.approx(lf.static_friction(p, j, v), rel=1e-9), (j, v)
        expect = {0: 25.0 * np.sign(v) + 8.0 * v,
                  1: np.sign(v) * (30.0 + 15.0 * np.exp(-(v / 0.05) ** 2)) + 8.0 * v}
        for j, f in expect.items():
            assert lf.static_friction(p, j, v) == pytest.approx(f, rel=1e-12)
        p2 = lf.scale_levels(p, 2.0)
        for j in range(4):
            assert lf.static_friction(p2, j, v) - 8.0 * v == pytest.approx(2 * (lf.static_friction(p, j, v) - 8.0 * v),
                                                                            rel=1e-12)
    lstm = p._replace(kind=np.array([lf.FrictionKind.LSTM] + [0] * 5, np.int64))
    with pytest.raises(ValueError):
        lf.scale_levels(lstm, 2.0)
