"""Generated diagnosis cases: synthetic records with a hidden effect of known size.

Used by ``greybench bench diagnose`` (confusion matrix) and the diagnosis tests: the plant
(:mod:`identify.plant`) hides one effect at a magnitude chosen so that its identifiable torque is a
given multiple of the noise RMS, and :func:`identify.diagnosis.diagnose` must name it blind. The
heavy-joint cases (:func:`run_heavy_case`, ``bench diagnose --heavy``) hide an effect of its
physical size (:mod:`identify.heavy_joint`) in motor-current records at a noise of a few per cent of
the friction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identify.diagnosis import CANDIDATES
from identify.diagnosis import diagnose as run_diagnosis
from identify.heavy_joint import HeavyCase


def effect_rms(effect: str, t, q, qd, qdd, seed: int, magnitude: float = 1.0, identifiable: bool = True) -> float:
    """RMS torque [Nm] the hidden ``effect`` adds at ``magnitude``.

    Same seed, same noise: the difference of the records with and without the effect is
    exactly the effect's torque. With ``identifiable`` (the default used for the generated
    cases), the part that the baseline's own parameters absorb is removed first -- the
    least-squares projection on the plant's dry friction, ``qd``, ``qdd`` and a constant, i.e.
    what refitting the friction levels, viscous coefficient, inertia and offset soaks up. A
    temperature effect on a record that stays at one temperature only changes the levels
    and is no error of a model fitted there; the identifiable RMS is what a model *must*
    get wrong without the effect.
    """
    from identify.plant import PlantConfig, synthesize

    a = synthesize(t, q, qd, qdd, seed=seed)
    b = synthesize(t, q, qd, qdd, seed=seed, effect=effect, magnitude=magnitude)
    d = b.frame["tau"].to_numpy() - a.frame["tau"].to_numpy()
    if identifiable:
        qd_s = a.frame["qd"].to_numpy()
        dry = a.friction - PlantConfig().nu * qd_s
        X = np.column_stack([dry, qd_s, a.frame["qdd"].to_numpy(), np.ones(d.size)])
        beta, *_ = np.linalg.lstsq(X, d, rcond=None)
        d = d - X @ beta
    return float(np.sqrt(np.mean(d ** 2)))


def magnitude_for(effect: str, ratio: float, t, q, qd, qdd, seed: int, noise: float = 0.02) -> float:
    """Plant ``magnitude`` at which the effect's identifiable RMS (:func:`effect_rms`) is ``ratio``
    times the noise RMS [-] (a few secant steps: the temperature effect is not linear in it)."""
    target = ratio * noise
    m = target / max(effect_rms(effect, t, q, qd, qdd, seed), 1e-12)
    for _ in range(3):
        r = effect_rms(effect, t, q, qd, qdd, seed, m)
        if abs(r - target) < 0.02 * target:
            break
        m *= target / max(r, 1e-12)
    return float(m)


def generated_cases(n_cases: int, seed: int = 0, ratios=(2.0, 3.0, 5.0, 10.0), clean_share: float = 0.25):
    """Seeded cases ``(effect, ratio, train_seed, test_seed)``.

    A share ``clean_share`` of the cases is clean (``none``); the rest cycle through the six
    effects so each appears about equally often, in a seeded random order, each at a ratio
    (identifiable effect RMS / noise RMS, :func:`effect_rms`) drawn from ``ratios``.
    """
    rng = np.random.default_rng(seed)
    from identify.plant import Effect

    effects = [c.value for c in CANDIDATES if c.value in {e.value for e in Effect}]  # what the plant can hide
    n_clean = int(round(clean_share * n_cases))
    kinds = ["none"] * n_clean + [effects[i % len(effects)] for i in range(n_cases - n_clean)]
    kinds = [kinds[i] for i in rng.permutation(len(kinds))]
    cases = []
    for i, effect in enumerate(kinds):
        ratio = 0.0 if effect == "none" else float(rng.choice(ratios))
        cases.append((effect, ratio, 1000 + i, 5000 + i))
    return cases


def run_case(effect: str, ratio: float, train_seed: int, test_seed: int, train_traj, test_traj, generations: int = 15):
    """Synthesise a train/test pair with a hidden effect and diagnose it blind; returns the result."""
    from identify.plant import synthesize
    from identify.records import validate_frame

    mag = 0.0 if effect == "none" else magnitude_for(effect, ratio, train_traj.t, train_traj.q, train_traj.qd,
                                                     train_traj.qdd, train_seed)
    recs = []
    for traj, s, name in ((train_traj, train_seed, "train"), (test_traj, test_seed, "test")):
        frame = synthesize(traj.t, traj.q, traj.qd, traj.qdd, seed=s, effect=effect, magnitude=mag).frame
        recs.append(validate_frame(frame, f"{name}-{effect}-{s}"))
    return run_diagnosis(recs[0], recs[1], generations=generations), mag


@dataclass(frozen=True)
class HeavyOutcome:
    """One generated heavy-joint case diagnosed blind (:mod:`identify.heavy_joint`).

    Attributes
    ----------
    case : HeavyCase
    named : str
        The top cause the diagnosis named (``none`` when nothing).
    causes : tuple of str
        Every named cause.
    noise_rms : float
        RMS of the test record's measurement error [Nm] (the generator's truth).
    baseline_rmse, extended_rmse : float
        Held-out RMSE of the LuGre baseline and of the extended model [Nm].
    """

    case: HeavyCase
    named: str
    causes: tuple[str, ...]
    noise_rms: float
    baseline_rmse: float
    extended_rmse: float

    @property
    def right(self) -> bool:
        return self.named == self.case.effect

    @property
    def extended_over_noise(self) -> float:
        """Extended model's held-out RMSE over the measurement error's RMS [-]."""
        return self.extended_rmse / self.noise_rms


def heavy_trajectories(robot_file, duration: float, axis: int = 2):
    """Training (Universal Trajectory) and test trajectories of a heavy joint: ``axis`` of ``robot_file``'s
    limits, ``duration`` [s] at 1 kHz."""
    from identify.axis_limits import load_axis_limits
    from identify.trajectories import test_trajectory, universal_trajectory

    limits = load_axis_limits(robot_file, axis)
    return universal_trajectory(limits, duration=duration), test_trajectory(limits, duration=duration)


def run_heavy_case(case: HeavyCase, train_traj, test_traj, generations: int = 15) -> HeavyOutcome:
    """Generate the case's heavy-joint records and diagnose them blind."""
    from identify.heavy_joint import case_records

    train, test, _, truth = case_records(case, train_traj, test_traj)
    res = run_diagnosis(train, test, generations=generations)
    return HeavyOutcome(case=case, named=res.cause.value, causes=tuple(c.value for c in res.analysis.causes),
                        noise_rms=truth.noise_rms, baseline_rmse=res.baseline_test.rmse,
                        extended_rmse=res.extended_test.rmse)
