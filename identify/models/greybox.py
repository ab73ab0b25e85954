"""The grey-box LuGre model: LuGre with its static curve g(qd) learned by a small MLP (paper 2.3.1).

Model (paper eqs. 7-9 with eq. 5 replaced by a network, Fig. 2)::

    tau_F = s0*z + s1*zdot + nu*qd,   zdot = qd - s0*|qd|*z/g(qd),   g = MLP(qd) > 0
    tau   = tau_F + J*qdd + c          (J, c co-identified when the record has no tau_rb)
    tau   = tau_F + c + tau_rb         (with tau_rb: only the torque offset c, predicted with tau_F)

- ``g``: one hidden layer of 10 sigmoid nodes, softplus output times a torque scale, so
  g > 0 by construction. Its input is the speed through a fixed log compression
  ``x = log(1 + |v|/v_ref) / log(1 + v_max/v_ref)`` (``v_ref = v_max/1000``): the Stribeck
  dip lives at speeds hundreds of times below the top speed, and on a linear input scale ten
  sigmoids would need huge weights to resolve it. The paper writes g(qd) without saying
  whether it is even; like its eq. 5, g here depends on the speed |qd| only, which gives all
  ten nodes to the shape of the curve instead of spending half of them on mirroring it
  (direction-dependent friction levels are therefore outside this model).
- s0 = exp(.), s1 = softplus(.), nu = softplus(.) (eqs. 3, 6, 9: positive by construction);
  each raw parameter is scaled to be of order one at its initial value.
- Normalisation (velocity reference and top speed, torque scale) is stored in buffers, so a
  saved network predicts on its own.

Bristle state, exactly and in parallel: the state is carried as ``w = s0*z`` [Nm] (no tiny
numbers), and with the velocity constant over a sample interval the exact update is the
linear recurrence ``w[k+1] = a[k]*w[k] + b[k]``, ``a = exp(-s0*|v|*dt/g)``,
``b = (1 - a)*g*sgn(v)`` (modelling notes 2), evaluated by the associative scan of
:mod:`identify.models.scan`. The paper does not say which velocity holds over an interval;
a record's qd is a *sample*, so the interval's velocity is taken as the mean of its two end
samples (trapezoid). On the synthetic plant this cuts the discretisation error of the exact
update at 1 kHz tenfold (0.018 -> 0.002 Nm RMS) against holding the first sample.

Initialisation, for robust training: a model-free static curve (piecewise linear in the
compressed velocity, by bounded least squares on the sliding samples) which the MLP is first
fitted to; s0 is then chosen on a logarithmic grid with s1, nu, J, c
solved by bounded least squares for each candidate (the bristle states from the numba
kernel). Adam then trains everything together on the full record.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from scipy.optimize import lsq_linear
from torch import nn

from identify.models.base import FrictionModel
from identify.models.lugre import relative_bounds
from identify.models.lugre_kernel import bristle_states
from identify.models.scan import linear_recurrence
from identify.records import AxisRecord
from identify.training import DTYPE, TrainingHistory, count_parameters, deterministic, train

NETWORK_FILE = "network.pt"


def _inverse_softplus(y: float) -> float:
    y = max(float(y), 1e-12)
    return y + math.log(-math.expm1(-y)) if y < 30 else y


def interval_velocity(qd: torch.Tensor) -> torch.Tensor:
    """Velocity over each sample interval [rad/s]: mean of its end samples (the last interval
    repeats the last sample), see the module docstring."""
    return torch.cat([0.5 * (qd[1:] + qd[:-1]), qd[-1:]])


def bristle_recurrence(v: torch.Tensor, dt: torch.Tensor, g: torch.Tensor, s0: torch.Tensor,
                       w0: torch.Tensor) -> torch.Tensor:
    """Scaled bristle states ``w = s0*z`` [Nm] at every sample by the exact update and the scan.

    Parameters
    ----------
    v : Tensor (n,)
        Velocity held over interval k [rad/s].
    dt : Tensor (n,)
        Interval length [s].
    g : Tensor (n,)
        Static level g(v[k]) [Nm], > 0.
    s0 : Tensor
        Bristle stiffness [Nm/rad].
    w0 : Tensor
        Initial state s0*z[0] [Nm].

    Returns
    -------
    Tensor (n,)
        ``w[0..n-1]``; equals ``s0 * bristle_states(v, dt, g, s0)`` of the numba kernel.
    """
    a = torch.exp(-s0 * v.abs() * dt / g)
    b = (1.0 - a) * g * torch.sign(v)
    return linear_recurrence(a[:-1], b[:-1], w0)


class StaticLevelNet(nn.Module):
    """g(v) [Nm] = tau_scale * softplus(MLP(x(v))), one hidden layer of ``hidden`` sigmoid nodes.

    Parameters
    ----------
    v_max : float
        Velocity scale [rad/s] (largest |qd| of the training record).
    tau_scale : float
        Torque scale [Nm].
    hidden : int
        Hidden nodes (paper: 10).
    """

    # buffers (register_buffer), declared for the type checker
    v_max: torch.Tensor
    v_ref: torch.Tensor
    tau_scale: torch.Tensor

    def __init__(self, v_max: float, tau_scale: float, hidden: int = 10):
        super().__init__()
        self.register_buffer("v_max", torch.tensor(float(v_max), dtype=DTYPE))
        self.register_buffer("v_ref", torch.tensor(float(v_max) / 1000.0, dtype=DTYPE))
        self.register_buffer("tau_scale", torch.tensor(float(tau_scale), dtype=DTYPE))
        self.hidden = nn.Linear(1, hidden, dtype=DTYPE)
        self.out = nn.Linear(hidden, 1, dtype=DTYPE)
        # sigmoid centres spread over the compressed velocity range [-1, 1]
        # sigmoid steps spread evenly over the compressed speed range [0, 1]
        with torch.no_grad():
            centres = torch.linspace(0.05, 0.95, hidden, dtype=DTYPE)
            self.hidden.weight.fill_(2.0 * hidden)
            self.hidden.bias.copy_(-self.hidden.weight[:, 0] * centres)

    def features(self, v: torch.Tensor) -> torch.Tensor:
        """Compressed speed x = log(1 + |v|/v_ref) / log(1 + v_max/v_ref) [-], 1 at v_max."""
        return torch.log1p(v.abs() / self.v_ref) / torch.log1p(self.v_max / self.v_ref)

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        h = torch.sigmoid(self.hidden(self.features(v).unsqueeze(-1)))
        return self.tau_scale * (nn.functional.softplus(self.out(h).squeeze(-1)) + 1e-6)


@dataclass
class GreyBoxOutput:
    """One forward pass over a record.

    Attributes
    ----------
    friction : Tensor
        tau_F [Nm] per sample.
    total : Tensor
        tau_F + J*qdd + c, or tau_F when the rigid part is known [Nm].
    w : Tensor
        Scaled bristle state s0*z [Nm].
    """

    friction: torch.Tensor
    total: torch.Tensor
    w: torch.Tensor


class GreyBoxLuGreNet(nn.Module):
    """The grey-box LuGre physics module (plain ``nn.Module``), see the module docstring.

    Parameters
    ----------
    v_max : float
        Velocity scale [rad/s].
    tau_scale : float
        Torque scale [Nm].
    acc_scale : float
        Acceleration scale [rad/s^2] (of the inertia parameter).
    s0, s1, nu : float
        Initial LuGre parameters [Nm/rad], [Nm s/rad], [Nm s/rad].
    J, c : float
        Initial inertia [kg m^2] and offset [Nm].
    rigid : bool
        Co-identify J and c (no tau_rb in the record).
    hidden : int
        Hidden nodes of g.
    """

    # buffers (register_buffer), declared for the type checker
    s1_scale: torch.Tensor
    nu_scale: torch.Tensor
    J_scale: torch.Tensor
    c_scale: torch.Tensor

    def __init__(self, v_max: float, tau_scale: float, acc_scale: float, s0: float = 1e4, s1: float = 1.0,
                 nu: float = 0.1, J: float = 0.0, c: float = 0.0, rigid: bool = True, hidden: int = 10):
        super().__init__()
        self.rigid = rigid
        self.level = StaticLevelNet(v_max, tau_scale, hidden)
        # Raw values must not start far below zero, where softplus is flat and a parameter would
        # never move: s1 (weakly identified, often solved as 0 at the start) starts at a
        # torque-over-speed scale, nu (well identified by the sliding samples) at >= 1% of it.
        s1, nu = max(s1, tau_scale / v_max), max(nu, 0.01 * tau_scale / v_max)
        self.register_buffer("s1_scale", torch.tensor(max(s1, tau_scale / v_max), dtype=DTYPE))
        self.register_buffer("nu_scale", torch.tensor(max(nu, tau_scale / v_max), dtype=DTYPE))
        self.register_buffer("J_scale", torch.tensor(tau_scale / acc_scale, dtype=DTYPE))
        self.register_buffer("c_scale", torch.tensor(tau_scale, dtype=DTYPE))
        self.log_s0 = nn.Parameter(torch.tensor(math.log(s0), dtype=DTYPE))
        self.raw_s1 = nn.Parameter(torch.tensor(_inverse_softplus(s1 / float(self.s1_scale)), dtype=DTYPE))
        self.raw_nu = nn.Parameter(torch.tensor(_inverse_softplus(nu / float(self.nu_scale)), dtype=DTYPE))
        self.raw_J = nn.Parameter(torch.tensor(J / float(self.J_scale), dtype=DTYPE), requires_grad=rigid)
        # the offset is co-identified with or without tau_rb (a torque-reading bias, base module)
        self.raw_c = nn.Parameter(torch.tensor(c / float(self.c_scale), dtype=DTYPE))

    # physical parameters, positive by construction
    @property
    def s0(self) -> torch.Tensor:
        return torch.exp(self.log_s0)

    @property
    def s1(self) -> torch.Tensor:
        return self.s1_scale * nn.functional.softplus(self.raw_s1)

    @property
    def nu(self) -> torch.Tensor:
        return self.nu_scale * nn.functional.softplus(self.raw_nu)

    @property
    def J(self) -> torch.Tensor:
        return self.J_scale * self.raw_J

    @property
    def c(self) -> torch.Tensor:
        return self.c_scale * self.raw_c

    def forward(self, qd: torch.Tensor, qdd: torch.Tensor, dt: torch.Tensor) -> GreyBoxOutput:
        s0 = self.s0
        g = self.level(qd)
        v_int = interval_velocity(qd)
        w0 = g[0] * torch.sign(qd[0])  # steady state of the first velocity (zero at rest)
        w = bristle_recurrence(v_int, dt, self.level(v_int), s0, w0)
        friction = w + self.s1 * (qd - qd.abs() * w / g) + self.nu * qd
        if not self.rigid:
            friction = friction + self.c
        total = friction + self.J * qdd + self.c if self.rigid else friction
        return GreyBoxOutput(friction=friction, total=total, w=w)

    def physical_parameters(self) -> dict[str, float]:
        p = {"s0": self.s0, "s1": self.s1, "nu": self.nu}
        if self.rigid:
            p["J"] = self.J
        p["c"] = self.c
        return {k: float(v.detach()) for k, v in p.items()}


def forward_recurrent(net: GreyBoxLuGreNet, qd: torch.Tensor, qdd: torch.Tensor, dt: torch.Tensor) -> torch.Tensor:
    """The same model as ``net(qd, qdd, dt).total``, stepped sample by sample in Python.

    The straightforward recurrent implementation (what the scan replaces): per step the level
    network, the exact update and the friction output. Reference for tests and the benchmark
    baseline only: O(n) Python steps.
    """
    s0, s1, nu = net.s0, net.s1, net.nu
    v_int = interval_velocity(qd)
    w = net.level(qd[:1])[0] * torch.sign(qd[0])
    out = []
    for k in range(qd.shape[0]):
        v = qd[k:k + 1]
        g = net.level(v)[0]
        f = w + s1 * (qd[k] - qd[k].abs() * w / g) + nu * qd[k]
        out.append(f + net.J * qdd[k] + net.c if net.rigid else f + net.c)
        gi = net.level(v_int[k:k + 1])[0]
        a = torch.exp(-s0 * v_int[k].abs() * dt[k] / gi)
        w = a * w + (1.0 - a) * gi * torch.sign(v_int[k])
    return torch.stack(out)


def record_tensors(record: AxisRecord) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(qd, qdd, dt, friction target) of a record as float64 tensors."""
    def as_t(x):
        return torch.tensor(np.asarray(x, dtype=float), dtype=DTYPE)
    return as_t(record.qd), as_t(record.qdd), as_t(record.dt), as_t(record.friction_target)


def _fit_level_to_curve(level: StaticLevelNet, v: torch.Tensor, g_target: torch.Tensor, steps: int, seed: int) -> None:
    """Pre-fit the level network to a known static curve (initialisation only).

    The output layer is solved by ridge least squares on the inverse-softplus target with the
    hidden sigmoids as they are, then everything is refined by a few Adam steps.
    """
    with torch.no_grad():
        h = torch.sigmoid(level.hidden(level.features(v).unsqueeze(-1)))
        H = torch.cat([h, torch.ones_like(h[:, :1])], dim=1)
        y = g_target / level.tau_scale
        target = torch.where(y > 20, y, torch.log(torch.expm1(y.clamp_min(1e-6))))
        sol = torch.linalg.solve(H.T @ H + 1e-6 * torch.eye(H.shape[1], dtype=DTYPE), H.T @ target)
        level.out.weight.copy_(sol[:-1].reshape(1, -1))
        level.out.bias.copy_(sol[-1:])
    with deterministic(seed):
        opt = torch.optim.Adam(level.parameters(), lr=0.01)
        for _ in range(steps):  # a 1-D curve of a few hundred points: a millisecond per step
            opt.zero_grad()
            loss = torch.mean(((level(v) - g_target) / level.tau_scale) ** 2)
            loss.backward()
            opt.step()


def _hat_basis(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Piecewise-linear (hat) basis functions on ``knots`` evaluated at ``x`` (clamped)."""
    x = np.clip(x, knots[0], knots[-1])
    eye = np.eye(knots.size)
    return np.column_stack([np.interp(x, knots, eye[j]) for j in range(knots.size)])


def _static_level_estimate(record: AxisRecord, level: StaticLevelNet, rigid: bool, v_eval: np.ndarray,
                           n_knots: int = 14) -> np.ndarray:
    """A model-free static level g(v) [Nm] at ``v_eval`` for initialisation.

    Assumes steady sliding (tau_F = sgn(v) g(|v|) + nu*v) with g piecewise linear in the
    compressed velocity of :class:`StaticLevelNet`, solved by bounded linear least squares
    together with nu, J, c. Robust where a parametric Stribeck fit can get stuck, and
    indifferent to the curve's shape (the point of the grey-box model).
    """
    with torch.no_grad():
        x = level.features(torch.tensor(record.qd, dtype=DTYPE)).numpy()
        xe = level.features(torch.as_tensor(v_eval, dtype=DTYPE)).numpy()
    # Below 1% of top speed the bristles are deflected (pre-sliding) and friction lies under
    # the static level: those samples are left out and the level is held constant there.
    x_min = float(level.features(torch.tensor(0.01, dtype=DTYPE) * level.v_max))
    knots = np.linspace(x_min, 1.0, n_knots)
    keep = x >= x_min
    H = _hat_basis(x[keep], knots) * np.sign(record.qd[keep])[:, None]
    cols = [H, record.qd[keep, None]] + ([record.qdd[keep, None]] if rigid else []) + [np.ones((int(keep.sum()), 1))]
    X = np.hstack(cols)
    lb = np.zeros(X.shape[1])
    lb[-1] = -np.inf  # the offset c
    res = lsq_linear(X, record.friction_target[keep], bounds=(lb, np.full(X.shape[1], np.inf)), method="bvls")
    return _hat_basis(xe, knots) @ res.x[:n_knots]


def _initial_lugre(record: AxisRecord, level: StaticLevelNet, rigid: bool) -> dict[str, float]:
    """s0 by a log grid, with (s1, nu, J, c) solved by bounded least squares per candidate."""
    qd = np.ascontiguousarray(record.qd, dtype=float)
    v_int = np.append(0.5 * (qd[1:] + qd[:-1]), qd[-1])
    dt = np.ascontiguousarray(record.dt, dtype=float)
    y = record.friction_target
    with torch.no_grad():
        g_int = level(torch.tensor(v_int, dtype=DTYPE)).numpy()
        g = level(torch.tensor(qd, dtype=DTYPE)).numpy()
    best = None
    (s0_lo, s0_hi), _ = relative_bounds(y, qd)  # the LuGre search range, from the record's scales
    for s0 in np.geomspace(s0_lo, s0_hi, 17):
        z = bristle_states(v_int, dt, g_int, s0)
        z[0] = np.sign(qd[0]) * g[0] / s0
        w = s0 * z
        cols = [qd - np.abs(qd) * w / g, qd] + ([record.qdd] if rigid else []) + [np.ones(record.n)]
        X = np.column_stack(cols)
        lb = np.array([0.0, 0.0] + ([0.0] if rigid else []) + [-np.inf])
        res = lsq_linear(X, y - w, bounds=(lb, np.full(X.shape[1], np.inf)), method="bvls")
        sse = float(np.sum((X @ res.x - (y - w)) ** 2))
        if best is None or sse < best[0]:
            best = (sse, s0, res.x)
    assert best is not None  # the s0 grid has 17 points
    _, s0, x = best
    p = {"s0": float(s0), "s1": float(x[0]), "nu": float(x[1]), "c": float(x[-1])}
    if rigid:
        p["J"] = float(x[2])
    return p


class GreyBoxLuGre(FrictionModel):
    """Grey-box LuGre friction model trained by Adam on the full record (paper 2.3.1).

    Parameters
    ----------
    epochs : int
        Adam steps over the full record.
    lr : float
        Initial learning rate (cosine decay).
    hidden : int
        Hidden sigmoid nodes of the static-level network (paper: 10).
    seed : int
        Torch seed (initialisation and training).
    """

    name = "greybox"
    units = {"s0": "Nm/rad", "s1": "Nm s/rad", "nu": "Nm s/rad", "J": "kg m^2", "c": "Nm"}

    def __init__(self, epochs: int = 500, lr: float = 0.05, hidden: int = 10, seed: int = 0):
        self.epochs = epochs
        self.lr = lr
        self.hidden = hidden
        self.seed = seed

    def build(self, record: AxisRecord) -> GreyBoxLuGreNet:
        """The network initialised from the record (model-free static level, s0 grid), untrained."""
        rigid = record.tau_rb is None
        v_max = float(np.max(np.abs(record.qd))) or 1.0
        y = record.friction_target
        tau_scale = float(np.std(y)) or 1.0
        acc_scale = float(np.std(record.qdd)) or 1.0
        with deterministic(self.seed):
            net = GreyBoxLuGreNet(v_max, tau_scale, acc_scale, rigid=rigid, hidden=self.hidden)
        v = torch.as_tensor(np.concatenate([-np.geomspace(v_max, v_max * 1e-4, 200), [0.0],
                                            np.geomspace(v_max * 1e-4, v_max, 200)]), dtype=DTYPE)
        g_target = torch.as_tensor(np.maximum(_static_level_estimate(record, net.level, rigid, v.numpy()),
                                              0.05 * tau_scale), dtype=DTYPE)
        _fit_level_to_curve(net.level, v, g_target, steps=300, seed=self.seed)
        init = _initial_lugre(record, net.level, rigid)
        with deterministic(self.seed):
            fresh = GreyBoxLuGreNet(v_max, tau_scale, acc_scale, rigid=rigid, hidden=self.hidden, **init)
        fresh.level.load_state_dict(net.level.state_dict())
        self.init_params_ = init
        return fresh

    def _fit(self, record: AxisRecord) -> None:
        net = self.build(record)
        qd, qdd, dt, y = record_tensors(record)
        scale = net.level.tau_scale

        def loss_fn(module, batch):
            out = module(*batch[:3])
            return torch.mean(((out.total - batch[3]) / scale) ** 2)

        self.history_: TrainingHistory = train(net, loss_fn, [(qd, qdd, dt, y)], epochs=self.epochs, lr=self.lr,
                                               seed=self.seed)
        self.net_ = net
        self.params_ = net.physical_parameters()

    def forward_record(self, record: AxisRecord) -> GreyBoxOutput:
        self._check_fitted()
        qd, qdd, dt, _ = record_tensors(record)
        with torch.no_grad():
            return self.net_(qd, qdd, dt)

    def _friction(self, record: AxisRecord) -> np.ndarray:
        return self.forward_record(record).friction.numpy().copy()

    def static_curve(self, v: np.ndarray) -> np.ndarray:
        """Learned static level g(v) [Nm]."""
        self._check_fitted()
        with torch.no_grad():
            return self.net_.level(torch.as_tensor(np.asarray(v, dtype=float), dtype=DTYPE)).numpy()

    def n_parameters(self) -> int:
        self._check_fitted()
        return count_parameters(self.net_)

    def _save_extra(self, directory: Path) -> None:
        torch.save({"rigid": self.net_.rigid, "hidden": self.hidden, "state": self.net_.state_dict()},
                   directory / NETWORK_FILE)

    def _load_extra(self, directory: Path) -> None:
        blob = torch.load(directory / NETWORK_FILE, weights_only=True)
        st = blob["state"]
        net = GreyBoxLuGreNet(float(st["level.v_max"]), float(st["level.tau_scale"]), 1.0, rigid=blob["rigid"],
                              hidden=int(blob["hidden"]))
        net.load_state_dict(st)
        net.eval()
        self.net_ = net
