"""Generated records of a heavy industrial robot joint, measured through its motor current.

The demo plant (:mod:`identify.plant`) is a small joint with a torque sensor; the Panda log of
``bench realdata`` has link-side torque sensors that hide most of the gear friction. This
generator stands for what neither covers: a heavy joint (an upper-arm axis with a reducer of the
RV-160E class) whose torque is read from the motor current, so the record holds the gear's whole
friction, the drive's gain error and the current reading's quantisation. Every law and default
is listed with its source, or marked *assumed*, in ``docs/heavy-joints.md``.

The joint follows the commanded trajectory (stiff position loop) and the drive reports::

    tau_true = J*qdd + G*sin(q + phi) + tau_F(qd, z; |tau_load|, T)
    tau      = quantise(gain * tau_true + noise, step)            # motor-current reading
    tau_rb   = gain * (J*qdd + G*sin(q + phi))                     # rigid-body model (IDIM-LS)
    tau_load = tau_rb                                              # the torque the gear carries

``tau_rb`` is what a rigid-body model identified from the same current readings predicts, so it
carries the same gain (an inverse-dynamics identification scales every parameter by it); the
friction a model learns from ``tau - tau_rb`` is then ``gain`` times the gear's. ``temp`` is the
gear temperature over a warm-up, ``T(t) = T_end - (T_end - T_0) exp(-(t - t0)/tau_w)``, with a
seeded start and rise, time-compressed into the record (a real gear warms over tens of minutes
to hours; the record holds the temperature range of a warm-up, not its duration).

The friction ``tau_F`` is LuGre (paper eqs. 5, 7-9) with a Stribeck curve whose Coulomb level is
a few per cent of the rated torque. One hidden effect (``effect``) may act on it, scaled by
``magnitude`` (1 = the default strength):

- ``load``: the levels grow with the carried torque, ``fc, fs *= 1 + k_load*|tau_load|/rated``
  (torque loss = idle loss + a share of the transferred torque);
- ``temperature``: the viscous coefficient falls as the lubricant warms, ``nu *= exp(-k_nu dT)``,
  and the dry levels by ``1 - k_fc dT``, ``dT = T - temp_ref``;
- ``asymmetry``: the levels are lower by ``asymmetry`` in the negative direction;
- ``position``: an additive ripple ``A sin(n q + 0.4)`` of order ``n = ripple_periods * N`` per rad
  (``ripple_periods`` cycles per input revolution of the reducer of ratio ``N``).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from enum import Enum

import numpy as np
import pandas as pd

from identify.errors import InputError
from identify.models.lugre_kernel import lugre_from_levels
from identify.models.static_curves import STATIC_CURVES


class HeavyEffect(str, Enum):
    """Hidden effects of the heavy joint (module docstring)."""

    NONE = "none"
    LOAD = "load"
    TEMPERATURE = "temperature"
    ASYMMETRY = "asymmetry"
    POSITION = "position"


@dataclass(frozen=True)
class HeavyJointConfig:
    """Parameters of the heavy joint, joint side, SI (``docs/heavy-joints.md``: source or *assumed*).

    Attributes
    ----------
    rated_torque : float
        Reducer rated output torque [Nm] (RV-160E class).
    gear_ratio : float
        Reducer ratio N [-].
    inertia : float
        Link and reflected rotor inertia J [kg m^2] (assumed).
    gravity_torque, gravity_phase : float
        Weight torque amplitude G [Nm] and phase phi [rad]: ``G sin(q + phi)`` (assumed).
    fc_share : float
        Coulomb level as a share of the rated torque [-] (a few per cent).
    fs_ratio : float
        Static over Coulomb level [-].
    vs : float
        Stribeck velocity [rad/s].
    delta : float
        Stribeck exponent [-].
    nu_share : float
        Viscous torque at 1 rad/s as a share of the rated torque [-] (``nu = nu_share*rated`` [Nm s/rad]).
    presliding : float
        Pre-sliding displacement [rad]; bristle stiffness ``s0 = fc/presliding`` [Nm/rad].
    s1_ratio : float
        Bristle damping as a share of the critical ``2 sqrt(s0 J)`` [-].
    gain_error_max : float
        The drive's gain error is drawn per joint from +-this share [-] (torque-constant tolerance).
    current_bits : int
        Resolution of the current reading [bit] over +-``peak_ratio`` x rated torque.
    peak_ratio : float
        Full scale of the current reading in rated torques [-].
    temp_ref : float
        Reference temperature of the friction parameters [degC].
    k_load : float
        Relative level increase per rated torque of |tau_load| [-] (``load`` effect).
    k_nu, k_fc : float
        Viscous decay [1/K] and dry-level decrease [1/K] with temperature (``temperature`` effect).
    asymmetry : float
        Relative level reduction for negative velocity [-] (``asymmetry`` effect).
    ripple_share : float
        Ripple amplitude as a share of the Coulomb level [-] (``position`` effect).
    ripple_periods : float
        Ripple cycles per input (motor-side) revolution [-]; joint-side order ``ripple_periods * N`` [1/rad].
    substeps : int
        Internal friction integration steps per record sample.
    """

    rated_torque: float = 1568.0
    gear_ratio: float = 256.857143
    inertia: float = 80.0
    gravity_torque: float = 600.0
    gravity_phase: float = 0.0
    fc_share: float = 0.03
    fs_ratio: float = 1.3
    vs: float = 0.05
    delta: float = 2.0
    nu_share: float = 0.01
    presliding: float = 2.909e-4
    s1_ratio: float = 0.05
    gain_error_max: float = 0.10
    current_bits: int = 16
    peak_ratio: float = 3.0
    temp_ref: float = 25.0
    k_load: float = 0.25
    k_nu: float = 0.02
    k_fc: float = 0.004
    asymmetry: float = 0.10
    ripple_share: float = 0.05
    ripple_periods: float = 1.0
    substeps: int = 10

    @property
    def fc(self) -> float:
        """Coulomb level [Nm]."""
        return self.fc_share * self.rated_torque

    @property
    def fs(self) -> float:
        """Static level [Nm]."""
        return self.fs_ratio * self.fc

    @property
    def nu(self) -> float:
        """Viscous coefficient [Nm s/rad]."""
        return self.nu_share * self.rated_torque

    @property
    def s0(self) -> float:
        """Bristle stiffness [Nm/rad]."""
        return self.fc / self.presliding

    @property
    def s1(self) -> float:
        """Bristle damping [Nm s/rad]."""
        return self.s1_ratio * 2.0 * float(np.sqrt(self.s0 * self.inertia))

    @property
    def ripple_order(self) -> float:
        """Joint-side ripple order [1/rad]."""
        return self.ripple_periods * self.gear_ratio

    @property
    def current_step(self) -> float:
        """Quantisation step of the torque read from the current [Nm]."""
        return 2.0 * self.peak_ratio * self.rated_torque / 2.0 ** self.current_bits

    def validate(self) -> HeavyJointConfig:
        for name in ("rated_torque", "gear_ratio", "inertia", "fc_share", "vs", "delta", "presliding", "current_bits",
                     "peak_ratio", "ripple_periods", "substeps"):
            if not getattr(self, name) > 0:
                raise InputError("must be > 0", source="<heavy joint>", field=name)
        if self.fs_ratio < 1:
            raise InputError("the static level must be >= the Coulomb level", source="<heavy joint>", field="fs_ratio")
        return self

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class HeavyRecord:
    """A generated heavy-joint record and the truth behind it.

    Attributes
    ----------
    frame : DataFrame
        ``t [s], q [rad], qd [rad/s], qdd [rad/s^2], tau [Nm], tau_rb [Nm], tau_load [Nm], temp [degC]``.
    config : HeavyJointConfig
    effect : HeavyEffect
    magnitude : float
        Scale of the effect [-].
    gain : float
        The drive's gain [-] (1 + its error).
    noise_rms : float
        RMS of the measurement error (Gaussian noise and quantisation) [Nm].
    friction : ndarray
        True joint friction at the samples [Nm] (before the gain).
    nominal_friction : ndarray
        The friction of the same gear at ``temp_ref`` without the hidden effect, times the gain [Nm]:
        the catalogue-style model a user would take as the "published" one.
    """

    frame: pd.DataFrame
    config: HeavyJointConfig
    effect: HeavyEffect
    magnitude: float
    gain: float
    noise_rms: float
    friction: np.ndarray
    nominal_friction: np.ndarray


def drive_gain(config: HeavyJointConfig, joint_seed: int) -> float:
    """The drive's gain [-] of one joint, ``1 + e`` with ``e`` uniform in +-``gain_error_max``; fixed per
    joint (seeded by ``joint_seed``), so its training and test records share it."""
    rng = np.random.default_rng([joint_seed, 7])
    return 1.0 + float(rng.uniform(-config.gain_error_max, config.gain_error_max))


def _friction(cfg: HeavyJointConfig, vf: np.ndarray, dtf: np.ndarray, qf: np.ndarray, load_f: np.ndarray,
              temp_f: np.ndarray, effect: HeavyEffect, s: float) -> np.ndarray:
    """LuGre friction on the fine grid [Nm] with the hidden effect."""
    scale = np.ones(vf.size)
    nu = np.full(vf.size, cfg.nu)
    if effect is HeavyEffect.LOAD:
        scale = scale * (1.0 + s * cfg.k_load * np.abs(load_f) / cfg.rated_torque)
    if effect is HeavyEffect.ASYMMETRY:
        scale = np.where(vf < 0, scale * (1.0 - s * cfg.asymmetry), scale)
    if effect is HeavyEffect.TEMPERATURE:
        dT = temp_f - cfg.temp_ref
        nu = nu * np.exp(-s * cfg.k_nu * dT)
        scale = scale * np.clip(1.0 - s * cfg.k_fc * dT, 0.2, None)
    g = STATIC_CURVES["stribeck"](vf, cfg.fc, cfg.fs, cfg.vs, cfg.delta) * scale
    f, _ = lugre_from_levels(vf, dtf, g, cfg.s0, cfg.s1, 0.0)
    f = f + nu * vf
    if effect is HeavyEffect.POSITION:
        f = f + s * cfg.ripple_share * cfg.fc * np.sin(cfg.ripple_order * qf + 0.4)
    return f


def warmup(t: np.ndarray, seed: int) -> np.ndarray:
    """Gear temperature [degC] over a warm-up: a seeded start of 18-26 degC rising towards 15-25 K more
    with a time constant of half the record (module docstring)."""
    rng = np.random.default_rng([seed, 3])
    t0, span = float(t[0]), float(t[-1] - t[0])
    start, rise = rng.uniform(18.0, 26.0), rng.uniform(15.0, 25.0)
    return start + rise * (1.0 - np.exp(-(t - t0) / (0.5 * span))) / (1.0 - np.exp(-2.0))


def generate(t: np.ndarray, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray, *, noise_share: float = 0.02,
             effect: HeavyEffect | str = HeavyEffect.NONE, magnitude: float = 1.0, seed: int = 0,
             joint_seed: int = 0, config: HeavyJointConfig | None = None) -> HeavyRecord:
    """A heavy-joint record following a trajectory (module docstring).

    Parameters
    ----------
    t, q, qd, qdd : ndarray
        Trajectory: time [s], position [rad], velocity [rad/s], acceleration [rad/s^2].
    noise_share : float
        RMS of the whole measurement error (Gaussian noise plus the current's quantisation) as a share
        of the Coulomb level [-]; at least the quantisation's own ``step/sqrt(12)``.
    effect : HeavyEffect
        The hidden effect.
    magnitude : float
        Its strength relative to the default [-].
    seed : int
        Seeds the noise and the warm-up.
    joint_seed : int
        Seeds the drive's gain (:func:`drive_gain`), shared by a joint's records.
    config : HeavyJointConfig
    """
    from scipy.interpolate import CubicHermiteSpline

    cfg = (config or HeavyJointConfig()).validate()
    effect = HeavyEffect(effect)
    if not noise_share >= 0:
        raise InputError("must be >= 0", field="noise_share")
    rng = np.random.default_rng([seed, 11])
    m = cfg.substeps
    dt = np.diff(t)
    tf = np.concatenate([(t[:-1, None] + dt[:, None] * (np.arange(m) / m)[None, :]).ravel(), t[-1:]])
    spline = CubicHermiteSpline(t, q, qd)
    qf, vf, af = spline(tf), spline(tf, 1), spline(tf, 2)
    dtf = np.append(np.diff(tf), tf[-1] - tf[-2])
    rigid_f = cfg.inertia * af + cfg.gravity_torque * np.sin(qf + cfg.gravity_phase)
    temp_f = warmup(tf, seed)
    idx = np.arange(t.size) * m
    friction = _friction(cfg, vf, dtf, qf, rigid_f, temp_f, effect, magnitude)[idx]
    nominal = _friction(cfg, vf, dtf, qf, rigid_f, temp_f, HeavyEffect.NONE, 0.0)[idx]
    gain = drive_gain(cfg, joint_seed)
    rigid = cfg.inertia * qdd + cfg.gravity_torque * np.sin(q + cfg.gravity_phase)
    step = cfg.current_step
    quant_rms = step / np.sqrt(12.0)
    sigma = float(np.sqrt(max((noise_share * cfg.fc) ** 2 - quant_rms ** 2, 0.0)))
    clean = gain * (rigid + friction)
    tau = step * np.round((clean + rng.normal(0.0, sigma, t.size)) / step)
    frame = pd.DataFrame({"t": t, "q": q, "qd": qd, "qdd": qdd, "tau": tau, "tau_rb": gain * rigid,
                          "tau_load": gain * rigid, "temp": temp_f[idx]})
    return HeavyRecord(frame=frame, config=cfg, effect=effect, magnitude=magnitude, gain=gain,
                       noise_rms=float(np.sqrt(np.mean((tau - clean) ** 2))), friction=friction,
                       nominal_friction=gain * nominal)


#: The hidden effects of the generated diagnosis cases, in a fixed order.
CASE_EFFECTS: tuple[str, ...] = tuple(e.value for e in HeavyEffect)
#: Strength of a case's effect: uniform in this range times the default [-].
MAGNITUDE_RANGE = (0.5, 1.5)


@dataclass(frozen=True)
class HeavyCase:
    """One seeded diagnosis case: a heavy joint's training and test records with one hidden effect.

    Attributes
    ----------
    effect : str
    noise_share : float
        Measurement error RMS / Coulomb level [-].
    magnitude : float
        Effect strength relative to the default [-] (0 for ``none``).
    seed : int
    """

    effect: str
    noise_share: float
    magnitude: float
    seed: int


def heavy_cases(per_cell: int, noise_shares=(0.01, 0.02, 0.03, 0.05), seed: int = 0,
                effects=CASE_EFFECTS) -> list[HeavyCase]:
    """``per_cell`` seeded cases for every effect and noise share, each with a strength drawn from
    :data:`MAGNITUDE_RANGE`."""
    rng = np.random.default_rng(seed)
    cases: list[HeavyCase] = []
    for _ in range(per_cell):
        for effect in effects:
            for share in noise_shares:
                mag = 0.0 if effect == "none" else float(rng.uniform(*MAGNITUDE_RANGE))
                cases.append(HeavyCase(effect, float(share), mag, 10_000 * (seed + 1) + len(cases)))
    return cases


def case_records(case: HeavyCase, train_traj, test_traj, config: HeavyJointConfig | None = None):
    """``(train, test, train_truth, test_truth)``: the case's records (:class:`~identify.records.AxisRecord`)
    and their :class:`HeavyRecord` truths; the two records share the joint (its gain), not the noise."""
    from identify.records import validate_frame

    out = []
    for traj, s, name in ((train_traj, case.seed, "train"), (test_traj, case.seed + 500_000, "test")):
        rec = generate(traj.t, traj.q, traj.qd, traj.qdd, noise_share=case.noise_share, effect=case.effect,
                       magnitude=case.magnitude, seed=s, joint_seed=case.seed, config=config)
        out.append((validate_frame(rec.frame, f"heavy-{name}-{case.effect}-{case.seed}"), rec))
    (train, tr), (test, te) = out
    return train, test, tr, te


def with_config(**changes) -> HeavyJointConfig:
    """The default configuration with some fields changed (validated)."""
    return replace(HeavyJointConfig(), **changes).validate()
