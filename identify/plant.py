"""A synthetic joint that makes measured-looking axis records (``greybench synth``).

A test and demo instrument, not the truth the fitters may peek at: it integrates its own
friction at a finer internal rate than the record it writes, adds sensor noise, and can
hide one effect that a plain LuGre model does not know about.

The joint follows the commanded trajectory exactly (position control with a stiff loop) and
the drive reports the torque that takes::

    tau = J*qdd + c + tau_F(qd, z; effect) + noise

It is modelled on a vertical first axis (paper: axis 1 of the MABI MAX 100): gravity and
payload load its gearbox (``tau_load``, written always) without adding torque about the axis,
so ``tau_load`` matters only through load-dependent friction. The gearbox temperature
``temp`` (written always) follows a first-order thermal model heated by friction losses,
from a seeded start temperature, so that it is not a function of time alone.

Hidden effects (``effect``), each scaled by ``magnitude`` (1 = the default strength):

- ``load``: Coulomb and static levels grow with |tau_load| (load-dependent friction,
  Bittencourt et al. 2010): ``fc, fs *= 1 + k_load*|tau_load|``.
- ``temperature``: viscous and Coulomb friction fall as the lubricant warms
  (Park et al. 2022): ``nu *= exp(-k_nu (T - T_ref))``, ``fc, fs *= 1 - k_fc (T - T_ref)``.
- ``position``: gear ripple, an additive ``A sin(order*q + phase)``.
- ``asymmetry``: lower friction levels in the negative direction.
- ``inertia``: the inertia about the axis follows the payload's radius, which also sets the
  gearbox load: ``J = J0*(1 + k*(|tau_load|/load_mean - 1))`` with ``k = inertia_step``.
  (A vertical axis 1 carries the payload's tilting moment m*g*r in its gearbox and its
  inertia m*r^2 about the axis; as the other axes move the payload out and in, both change
  together. The linear form is the first-order expansion about the nominal radius. A mass
  step at an arbitrary time, the earlier form, changed the inertia without the load it
  implies and cannot be predicted on another record.)
- ``drift``: a slow linear torque drift in time (e.g. sensor offset drift).
"""
from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, fields, replace
from enum import Enum
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.interpolate import CubicHermiteSpline, CubicSpline
from scipy.signal import lfilter

from identify.errors import InputError
from identify.models.lugre_kernel import lugre_from_levels
from identify.models.static_curves import STATIC_CURVES


class Effect(str, Enum):
    """Hidden effects the plant can add (see the module docstring)."""

    NONE = "none"
    LOAD = "load"
    TEMPERATURE = "temperature"
    POSITION = "position"
    ASYMMETRY = "asymmetry"
    INERTIA = "inertia"
    DRIFT = "drift"


@dataclass(frozen=True)
class PlantConfig:
    """Parameters of the synthetic joint (joint side, SI). Values *assumed*, of the scale of
    the paper's axis 1 (friction up to about +-3.5 Nm, s0 about 1.7e4 Nm/rad, Table 1).

    Attributes
    ----------
    inertia : float
        J [kg m^2].
    offset : float
        Constant torque offset c [Nm] (sensor offset).
    s0 : float
        Bristle stiffness [Nm/rad].
    s1 : float
        Bristle damping [Nm s/rad].
    nu : float
        Viscous coefficient [Nm s/rad].
    fc, fs : float
        Coulomb and static friction levels [Nm].
    vs : float
        Stribeck velocity [rad/s].
    delta : float
        Stribeck exponent [-].
    static_curve : str
        ``stribeck``, ``lorentzian`` or ``hump`` (:mod:`identify.models.static_curves`).
    noise : float
        Standard deviation of the torque sensor noise [Nm].
    substeps : int
        Internal integration steps per record sample.
    temp_ref : float
        Reference temperature of the friction parameters [degC].
    thermal_capacity : float
        Thermal capacity of the gearbox [J/K] (compressed so a one-minute record warms up).
    thermal_resistance : float
        Thermal resistance to ambient [K/W].
    load_mean, load_amplitude : float
        Load torque on the gearbox: mean and amplitude of its slow variation [Nm].
    load_period : float
        Period of the load variation [s].
    k_load : float
        Relative friction-level increase per Nm of |tau_load| [1/Nm].
    k_nu : float
        Viscous decay with temperature [1/K].
    k_fc : float
        Coulomb decrease with temperature [1/K].
    ripple_amplitude : float
        Position ripple amplitude [Nm].
    ripple_order : float
        Ripple spatial frequency [1/rad] (cycles per radian times 2 pi).
    asymmetry : float
        Relative reduction of the friction levels for negative velocity [-].
    inertia_step : float
        Relative inertia change per relative load change, ``k`` in
        ``J = J0*(1 + k*(|tau_load|/load_mean - 1))`` (``inertia`` effect) [-].
    drift_rate : float
        Torque drift [Nm/s] (``drift`` effect).
    """

    inertia: float = 0.5
    offset: float = 0.05
    s0: float = 1.7e4
    s1: float = 10.0
    nu: float = 0.5
    fc: float = 2.0
    fs: float = 2.8
    vs: float = 0.05
    delta: float = 2.0
    static_curve: str = "stribeck"
    noise: float = 0.02
    substeps: int = 10
    temp_ref: float = 25.0
    thermal_capacity: float = 4.0
    thermal_resistance: float = 6.0
    load_mean: float = 400.0
    load_amplitude: float = 300.0
    load_period: float = 23.0
    k_load: float = 4e-4
    k_nu: float = 0.02
    k_fc: float = 0.006
    ripple_amplitude: float = 0.15
    ripple_order: float = 11.0
    asymmetry: float = 0.15
    inertia_step: float = 0.3
    drift_rate: float = 0.006

    def validate(self, source: str = "<config>") -> PlantConfig:
        positive = ("inertia", "s0", "fc", "fs", "vs", "delta", "substeps", "thermal_capacity", "thermal_resistance",
                    "load_period", "ripple_order")
        for name in positive:
            if not getattr(self, name) > 0:
                raise InputError("must be > 0", source=source, field=name)
        for name in ("s1", "nu", "noise", "k_load", "k_nu", "k_fc", "ripple_amplitude", "asymmetry", "inertia_step"):
            if getattr(self, name) < 0:
                raise InputError("must be >= 0", source=source, field=name)
        if self.fs < self.fc:
            raise InputError("static level fs must be >= Coulomb level fc", source=source, field="fs")
        if self.static_curve not in STATIC_CURVES:
            raise InputError(f"unknown static curve '{self.static_curve}' (known: {', '.join(STATIC_CURVES)})",
                             source=source, field="static_curve")
        return self

    @classmethod
    def from_toml(cls, path: str | Path) -> PlantConfig:
        """Defaults overridden by the keys of a TOML file; unknown keys are refused."""
        p = Path(path)
        if not p.exists():
            raise InputError("plant config not found", source=str(p))
        try:
            data = tomllib.loads(p.read_text())
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"invalid TOML: {exc}", source=str(p)) from None
        known = {f.name: f.type for f in fields(cls)}
        for key, val in data.items():
            if key not in known:
                raise InputError(f"unknown key (known: {', '.join(known)})", source=str(p), field=key)
            if key == "static_curve":
                if not isinstance(val, str):
                    raise InputError("must be a string", source=str(p), field=key)
            elif not isinstance(val, (int, float)) or isinstance(val, bool):
                raise InputError("must be a number", source=str(p), field=key)
        # each value's type checked above against its field
        cfg = replace(cls(), **{k: (int(v) if k == "substeps" else v) for k, v in data.items()})  # type: ignore[arg-type]
        return cfg.validate(str(p))

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass
class SynthResult:
    """A synthetic record and the truth behind it (for tests and reports)."""

    frame: pd.DataFrame
    config: PlantConfig
    effect: Effect
    magnitude: float
    friction: np.ndarray  # true friction torque at the samples [Nm]


def _levels(cfg: PlantConfig, v: np.ndarray) -> np.ndarray:
    return STATIC_CURVES[cfg.static_curve](v, cfg.fc, cfg.fs, cfg.vs, cfg.delta)


def synthesize(t: np.ndarray, q: np.ndarray, qd: np.ndarray | None = None, qdd: np.ndarray | None = None, *,
               config: PlantConfig | None = None, effect: Effect | str = Effect.NONE, magnitude: float = 1.0,
               seed: int = 0, positions_only: bool = False) -> SynthResult:
    """Simulate the joint following a trajectory and return a measured-looking record.

    Parameters
    ----------
    t, q : ndarray
        Trajectory time [s] and position [rad].
    qd, qdd : ndarray, optional
        Velocity [rad/s] and acceleration [rad/s^2]; from a spline of ``q`` when absent.
    config : PlantConfig
        Plant parameters (defaults when None).
    effect : Effect
        The hidden effect.
    magnitude : float
        Scale of the effect's strength (1 = default).
    seed : int
        Seeds noise, start temperature and load phase.
    positions_only : bool
        Write ``t, q, tau, temp, tau_load`` only (velocity must then be derived).
    """
    cfg = (config or PlantConfig()).validate()
    effect = Effect(effect)
    rng = np.random.default_rng(seed)
    n = t.size
    m = cfg.substeps
    # Fine time grid: friction integrated at m substeps per sample.
    dt = np.diff(t)
    tf = np.concatenate([(t[:-1, None] + dt[:, None] * (np.arange(m) / m)[None, :]).ravel(), t[-1:]])
    spline = CubicHermiteSpline(t, q, qd) if qd is not None else CubicSpline(t, q)
    vf = spline(tf, 1)
    qf = spline(tf)
    if qd is None:
        qd = spline(t, 1)
    if qdd is None:
        qdd = spline(t, 2)
    dtf = np.append(np.diff(tf), tf[-1] - tf[-2])

    # Load on the gearbox: slow variation as the other axes move the payload (vertical axis 1).
    phase = rng.uniform(0, 2 * np.pi)
    load_f = cfg.load_mean + cfg.load_amplitude * np.sin(2 * np.pi * tf / cfg.load_period + phase)
    s = magnitude
    fc = np.full(tf.size, cfg.fc)
    fs = np.full(tf.size, cfg.fs)
    nu = np.full(tf.size, cfg.nu)
    if effect is Effect.LOAD:
        scale = 1.0 + s * cfg.k_load * np.abs(load_f)
        fc, fs = fc * scale, fs * scale
    if effect is Effect.ASYMMETRY:
        neg = vf < 0
        fc = np.where(neg, fc * (1 - s * cfg.asymmetry), fc)
        fs = np.where(neg, fs * (1 - s * cfg.asymmetry), fs)

    temp0 = rng.uniform(20.0, 32.0)
    temp_f = _thermal(cfg, vf, dtf, temp0)
    if effect is Effect.TEMPERATURE:
        dT = temp_f - cfg.temp_ref
        nu = nu * np.exp(-s * cfg.k_nu * dT)
        k = np.clip(1 - s * cfg.k_fc * dT, 0.2, None)
        fc, fs = fc * k, fs * k
    g = fc + (fs - fc) * (_levels(cfg, vf) - cfg.fc) / (cfg.fs - cfg.fc) if cfg.fs > cfg.fc else fc
    friction_f, _ = lugre_from_levels(vf, dtf, g, cfg.s0, cfg.s1, 0.0)
    friction_f = friction_f + nu * vf
    if effect is Effect.POSITION:
        friction_f = friction_f + s * cfg.ripple_amplitude * np.sin(cfg.ripple_order * qf + 0.4)

    idx = np.arange(n) * m
    friction = friction_f[idx]
    inertia = np.full(n, cfg.inertia)
    if effect is Effect.INERTIA:
        # payload radius moves load and inertia together (module docstring); J stays > 0
        rel = np.abs(load_f[idx]) / cfg.load_mean - 1.0
        inertia = cfg.inertia * np.clip(1.0 + s * cfg.inertia_step * rel, 0.05, None)
    tau = inertia * qdd + cfg.offset + friction
    if effect is Effect.DRIFT:
        tau = tau + s * cfg.drift_rate * (t - t[0])
    tau = tau + rng.normal(0.0, cfg.noise, n)
    frame = pd.DataFrame({"t": t, "q": q})
    if not positions_only:
        frame["qd"] = qd
        frame["qdd"] = qdd
    frame["tau"] = tau
    frame["temp"] = temp_f[idx]
    frame["tau_load"] = load_f[idx]
    return SynthResult(frame=frame, config=cfg, effect=effect, magnitude=magnitude, friction=friction)


def _thermal(cfg: PlantConfig, v: np.ndarray, dt: np.ndarray, temp0: float) -> np.ndarray:
    """Gearbox temperature [degC]: C dT/dt = P_loss - (T - T_amb)/R, P_loss = |(fc + nu|v|) v|.

    Exact exponential update per step (linear ODE with the loss held over the step).
    """
    p_loss = np.abs(v) * (cfg.fc + cfg.nu * np.abs(v))
    tau_th = cfg.thermal_capacity * cfg.thermal_resistance
    # T[k+1] = a*T[k] + (1 - a)*T_ss[k]: a first-order filter (sampling is regular).
    a = float(np.median(np.exp(-dt / tau_th)))
    drive = temp0 + cfg.thermal_resistance * p_loss
    temp, _ = lfilter([0.0, 1.0 - a], [1.0, -a], drive, zi=[a * temp0])
    return temp
