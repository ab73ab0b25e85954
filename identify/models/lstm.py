"""The black-box baseline: an LSTM from the velocity history to the torque (paper 2.3, ref. [38]).

    tau[k] = tau_scale * Linear(LSTM(qd/v_scale, qdd/a_scale)[k]) + J*qdd[k] + c

The recurrent net sees the normalised velocity and acceleration history; the inertia J and
offset c are co-identified as linear terms (as in every model of the project) when the
record has no ``tau_rb``, so the network only has to learn friction.

Training and prediction use the same windows: the record is cut into consecutive blocks of
``window`` samples, each preceded by ``warmup`` samples of history that run the LSTM state
in but are not scored. All blocks go through the LSTM as one batch (torch's LSTM kernel
steps through time internally; no Python loop over samples). Normalisation scales live in
buffers so the saved network predicts on its own.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from identify.models.base import FrictionModel
from identify.records import AxisRecord
from identify.training import DTYPE, TrainingHistory, count_parameters, train

NETWORK_FILE = "network.pt"


class LSTMFrictionNet(nn.Module):
    """LSTM (2 inputs -> ``hidden``) + linear read-out, plus linear J*qdd + c.

    Parameters
    ----------
    v_scale : float
        Velocity scale [rad/s].
    a_scale : float
        Acceleration scale [rad/s^2].
    tau_scale : float
        Torque scale [Nm].
    hidden : int
        LSTM hidden size.
    rigid : bool
        Co-identify J and c.
    """

    def __init__(self, v_scale: float, a_scale: float, tau_scale: float, hidden: int = 16, rigid: bool = True):
        super().__init__()
        self.rigid = rigid
        self.register_buffer("v_scale", torch.tensor(float(v_scale), dtype=DTYPE))
        self.register_buffer("a_scale", torch.tensor(float(a_scale), dtype=DTYPE))
        self.register_buffer("tau_scale", torch.tensor(float(tau_scale), dtype=DTYPE))
        self.lstm = nn.LSTM(2, hidden, batch_first=True, dtype=DTYPE)
        self.head = nn.Linear(hidden, 1, dtype=DTYPE)
        self.raw_J = nn.Parameter(torch.zeros((), dtype=DTYPE), requires_grad=rigid)
        self.raw_c = nn.Parameter(torch.zeros((), dtype=DTYPE), requires_grad=rigid)

    def forward(self, qd: torch.Tensor, qdd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(friction, total) [Nm] for batches of windows, shape (batch, time)."""
        x = torch.stack([qd / self.v_scale, qdd / self.a_scale], dim=-1)
        h, _ = self.lstm(x)
        friction = self.tau_scale * self.head(h).squeeze(-1)
        if not self.rigid:
            return friction, friction
        J = self.raw_J * self.tau_scale / self.a_scale
        return friction, friction + J * qdd + self.raw_c * self.tau_scale


def windows(n: int, window: int, warmup: int) -> np.ndarray:
    """Start indices of the warm-up+block windows covering ``0..n-1`` (see module docstring).

    Window i covers samples ``[s_i, s_i + warmup + window)`` with ``s_i = i*window - warmup``
    (clamped into the record); its scored part starts at ``max(s_i + warmup, 0)``.
    """
    starts = np.arange(0, n, window) - warmup
    return np.clip(starts, 0, max(n - (warmup + window), 0))


def _gather(x: np.ndarray, starts: np.ndarray, length: int) -> torch.Tensor:
    idx = starts[:, None] + np.arange(length)[None, :]
    return torch.tensor(x[np.minimum(idx, x.size - 1)], dtype=DTYPE)


class LSTMFriction(FrictionModel):
    """Black-box LSTM friction baseline.

    Parameters
    ----------
    hidden : int
        LSTM hidden size.
    window : int
        Scored samples per window.
    warmup : int
        History samples before each window [samples].
    epochs : int
        Adam passes over all windows (one batch).
    lr : float
        Initial learning rate (cosine decay).
    seed : int
        Torch seed.
    """

    name = "lstm"
    units = {"J": "kg m^2", "c": "Nm"}

    def __init__(self, hidden: int = 16, window: int = 400, warmup: int = 100, epochs: int = 60, lr: float = 0.02,
                 seed: int = 0):
        self.hidden = hidden
        self.window = window
        self.warmup = warmup
        self.epochs = epochs
        self.lr = lr
        self.seed = seed

    def _batches(self, record: AxisRecord) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, np.ndarray]:
        length = min(self.warmup + self.window, record.n)
        starts = windows(record.n, self.window, self.warmup)
        qd = _gather(np.asarray(record.qd, dtype=float), starts, length)
        qdd = _gather(np.asarray(record.qdd, dtype=float), starts, length)
        y = _gather(np.asarray(record.friction_target, dtype=float), starts, length)
        return qd, qdd, y, starts

    def _fit(self, record: AxisRecord) -> None:
        torch.manual_seed(self.seed)
        v_scale = float(np.max(np.abs(record.qd))) or 1.0
        a_scale = float(np.std(record.qdd)) or 1.0
        tau_scale = float(np.std(record.friction_target)) or 1.0
        net = LSTMFrictionNet(v_scale, a_scale, tau_scale, self.hidden, rigid=bool(self.rigid_))
        qd, qdd, y, _ = self._batches(record)
        warm = min(self.warmup, qd.shape[1] - 1)

        def loss_fn(module, batch):
            _, total = module(batch[0], batch[1])
            return torch.mean(((total - batch[2])[:, warm:] / module.tau_scale) ** 2)

        self.history_: TrainingHistory = train(net, loss_fn, [(qd, qdd, y)], epochs=self.epochs, lr=self.lr,
                                               seed=self.seed)
        self.net_ = net
        self.params_ = self._rigid_params()

    def _rigid_params(self) -> dict[str, float]:
        if not self.net_.rigid:
            return {}
        n = self.net_
        return {"J": float(n.raw_J * n.tau_scale / n.a_scale), "c": float(n.raw_c * n.tau_scale)}

    def _friction(self, record: AxisRecord) -> np.ndarray:
        qd, qdd, _, starts = self._batches(record)
        with torch.no_grad():
            friction, _ = self.net_(qd, qdd)
        out = np.empty(record.n)
        friction = friction.numpy()
        length = qd.shape[1]
        # each window writes its scored part; the first window also covers the record's start
        for i, s in enumerate(starts):
            first = 0 if i == 0 else min(self.warmup, length - 1)
            lo = s + first
            hi = min(s + length, record.n)
            out[lo:hi] = friction[i, first:hi - s]
        return out

    def n_parameters(self) -> int:
        self._check_fitted()
        return count_parameters(self.net_)

    def _save_extra(self, directory: Path) -> None:
        torch.save({"rigid": self.net_.rigid, "state": self.net_.state_dict()}, directory / NETWORK_FILE)

    def _load_extra(self, directory: Path) -> None:
        blob = torch.load(directory / NETWORK_FILE, weights_only=True)
        st = blob["state"]
        net = LSTMFrictionNet(float(st["v_scale"]), float(st["a_scale"]), float(st["tau_scale"]), self.hidden,
                              rigid=blob["rigid"])
        net.load_state_dict(st)
        net.eval()
        self.net_ = net
