"""The residual LuGre model: conventional LuGre plus an MLP on its residual (paper 2.3.1, ref. [62]).

    tau_friction = tau_LuGre(qd; GA-identified) + tau_scale * MLP(x)
    tau          = tau_friction + J*qdd + c  (co-identified)   or  + tau_rb  (given)

The conventional LuGre model (:class:`identify.models.lugre.LuGre`, genetic algorithm +
least squares) is fitted first; the network (2 hidden layers of 10 nodes, LeakyReLU, linear
output; paper 2.3.1) then learns what LuGre leaves, trained by Adam on the full record.
Its inputs, as in ref. [62] (velocity, internal state, LuGre torque), all dimensionless:

- the signed, log-compressed velocity ``sgn(v) log(1 + |v|/v_ref)/log(1 + v_max/v_ref)``
  (the Stribeck region spans decades of speed, see :mod:`identify.models.greybox`);
- the normalised bristle state ``s0*z/g(v)`` in [-1, 1] (pre-sliding vs sliding);
- the LuGre friction torque over the torque scale.

Both parts are saved (``lugre/`` sub-folder and ``network.pt``) and reload exactly.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from identify.models.base import FrictionModel
from identify.models.lugre import LuGre
from identify.models.lugre_kernel import lugre_stribeck
from identify.records import AxisRecord
from identify.training import DTYPE, TrainingHistory, count_parameters, train

NETWORK_FILE = "network.pt"
BASE_FOLDER = "lugre"


class ResidualNet(nn.Module):
    """MLP 3 -> 10 -> 10 -> 1 with LeakyReLU; normalisation scales in buffers.

    Parameters
    ----------
    v_max : float
        Velocity scale [rad/s].
    tau_scale : float
        Torque scale [Nm] of the inputs.
    res_scale : float
        Torque scale [Nm] of the output (the residual's spread).
    hidden : int
        Nodes per hidden layer (paper: 10).
    """

    # buffers (register_buffer), declared for the type checker
    v_max: torch.Tensor
    tau_scale: torch.Tensor
    res_scale: torch.Tensor

    def __init__(self, v_max: float, tau_scale: float, res_scale: float, hidden: int = 10):
        super().__init__()
        self.register_buffer("v_max", torch.tensor(float(v_max), dtype=DTYPE))
        self.register_buffer("tau_scale", torch.tensor(float(tau_scale), dtype=DTYPE))
        self.register_buffer("res_scale", torch.tensor(float(res_scale), dtype=DTYPE))
        self.mlp = nn.Sequential(nn.Linear(3, hidden, dtype=DTYPE), nn.LeakyReLU(0.01),
                                 nn.Linear(hidden, hidden, dtype=DTYPE), nn.LeakyReLU(0.01),
                                 nn.Linear(hidden, 1, dtype=DTYPE))
        last = self.mlp[-1]
        assert isinstance(last, nn.Linear)
        with torch.no_grad():  # start at zero correction: the model begins as plain LuGre
            last.weight.mul_(0.1)
            last.bias.zero_()

    def forward(self, qd: torch.Tensor, state: torch.Tensor, tau_lugre: torch.Tensor) -> torch.Tensor:
        """Residual torque [Nm]; ``state`` = s0*z/g [-], ``tau_lugre`` [Nm]."""
        v_ref = self.v_max / 1000.0
        x_v = torch.sign(qd) * torch.log1p(qd.abs() / v_ref) / torch.log1p(self.v_max / v_ref)
        x = torch.stack([x_v, state, tau_lugre / self.tau_scale], dim=-1)
        return self.res_scale * self.mlp(x).squeeze(-1)


class ResidualLuGre(FrictionModel):
    """Conventional LuGre + residual MLP (paper 2.3.1 after ref. [62]).

    Parameters
    ----------
    epochs : int
        Adam steps over the full record for the network.
    lr : float
        Initial learning rate (cosine decay).
    hidden : int
        Nodes per hidden layer (paper: 10).
    seed : int
        Seed of the GA and of torch.
    population, generations : int
        GA settings of the conventional LuGre part.
    """

    name = "residual"
    units = dict(LuGre.units)

    def __init__(self, epochs: int = 400, lr: float = 0.01, hidden: int = 10, seed: int = 0, population: int = 48,
                 generations: int = 50):
        self.epochs = epochs
        self.lr = lr
        self.hidden = hidden
        self.seed = seed
        self.population = population
        self.generations = generations

    def _lugre_inputs(self, record: AxisRecord) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(qd, normalised bristle state, LuGre friction) tensors."""
        p = self.base_.params_
        qd = np.ascontiguousarray(record.qd, dtype=float)
        z = np.empty(record.n)
        f = lugre_stribeck(qd, np.ascontiguousarray(record.dt, dtype=float), p["s0"], p["s1"], p["nu"], p["fc"],
                           p["fs"], p["vs"], p["delta"], z) + self.base_.offset()
        g = self.base_.static_curve(qd)
        def as_t(x):
            return torch.tensor(np.asarray(x, dtype=float), dtype=DTYPE)
        return as_t(qd), as_t(p["s0"] * z / g), as_t(f)

    def _fit(self, record: AxisRecord) -> None:
        self.base_ = LuGre(population=self.population, generations=self.generations, seed=self.seed).fit(record)
        qd, state, f = self._lugre_inputs(record)
        # what LuGre leaves of the friction target: J*qdd + c only when co-identified (with tau_rb
        # the target has already left the rigid body out; taking it off again subtracted it twice)
        residual = torch.tensor(record.friction_target - self.base_.target_part(record), dtype=DTYPE)
        v_max = float(np.max(np.abs(record.qd))) or 1.0
        torch.manual_seed(self.seed)
        net = ResidualNet(v_max, float(np.std(record.friction_target)) or 1.0, float(residual.std()) or 1.0,
                          self.hidden)
        scale = net.res_scale

        def loss_fn(module, batch):
            return torch.mean(((module(*batch[:3]) - batch[3]) / scale) ** 2)

        self.history_: TrainingHistory = train(net, loss_fn, [(qd, state, f, residual)], epochs=self.epochs,
                                               lr=self.lr, seed=self.seed)
        self.net_ = net
        self.params_ = dict(self.base_.params_)

    def _friction(self, record: AxisRecord) -> np.ndarray:
        qd, state, f = self._lugre_inputs(record)
        with torch.no_grad():
            return f.numpy() + self.net_(qd, state, f).numpy()

    def n_parameters(self) -> int:
        self._check_fitted()
        return len(self.params_) + count_parameters(self.net_)

    def _save_extra(self, directory: Path) -> None:
        self.base_.save(directory / BASE_FOLDER)
        torch.save({"hidden": self.hidden, "state": self.net_.state_dict()}, directory / NETWORK_FILE)

    def _load_extra(self, directory: Path) -> None:
        self.base_ = LuGre.load(directory / BASE_FOLDER)
        blob = torch.load(directory / NETWORK_FILE, weights_only=True)
        st = blob["state"]
        net = ResidualNet(float(st["v_max"]), float(st["tau_scale"]), float(st["res_scale"]), int(blob["hidden"]))
        net.load_state_dict(st)
        net.eval()
        self.net_ = net
