"""The black-box baseline: an LSTM from the motion history to the torque (paper 2.2.1, ref. [38]).

    tau[k] = tau_scale * Head([LSTM(x)[k], x[k]]) + J*qdd[k] + c

``x`` are causal features of the record (:mod:`identify.models.sequence_features`): the
velocity at three compressions (linear, tanh and signed log, so the net sees the sign changes
at pre-sliding speeds where ``qd/v_max`` is ~1e-4), the acceleration, and play-operator
deflections at log-spaced widths (the position history since the last reversals). ``Head`` is
a small tanh MLP on the LSTM state and the current features. The net knows no friction
physics (no bristle state, no Stribeck curve): it stays a black box. The inertia J and offset
c are co-identified as linear terms, as in every model of the project, when the record has no
``tau_rb``; they start from a linear least-squares fit so the net only has to learn friction.

Windows. The record is cut into consecutive blocks of ``window`` samples; each block is run
with the ``warmup`` samples before it, which set the LSTM state but are not scored. The record
is padded in front with ``warmup`` copies of its first sample (the joint at rest before the
record, the physically sound assumption for an unknown history) and at the end with copies of
its last sample (masked out), so every sample is scored exactly once, in training and in
prediction alike. All windows of a batch go through ``torch.nn.LSTM`` together (its kernel
steps through time internally; no Python loop over samples).

Precision: float32. Friction torques are ~3 Nm and the noise 0.02 Nm, six orders of
magnitude above float32 rounding, and the LSTM runs several times faster than in float64.
Normalisation lives in buffers, so the saved network predicts on its own.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from identify.errors import InputError
from identify.models.base import FrictionModel
from identify.models.sequence_features import DEFAULT_PLAY_WIDTHS, TANH_VELOCITY, FeatureScales, sequence_features
from identify.records import AxisRecord
from identify.training import TrainingHistory, count_parameters, deterministic, torch_threads, train

NETWORK_FILE = "network.pt"
#: Version of ``network.pt``; older LSTM folders (inputs qd, qdd only) must be refitted.
NETWORK_FORMAT = 2
#: Floating-point type of the LSTM (see the module docstring).
LSTM_DTYPE = torch.float32
#: Torch threads for fitting and predicting: the per-step matrix products of a 16-unit LSTM
#: are too small to share out (:func:`identify.training.torch_threads`); one thread also
#: makes results independent of the caller's thread setting.
LSTM_THREADS = 1


class LSTMFrictionNet(nn.Module):
    """LSTM over the features + tanh MLP read-out on [LSTM state, features], plus J*qdd + c.

    Parameters
    ----------
    v_scale : float
        Velocity scale of the features [rad/s].
    a_scale : float
        Acceleration scale [rad/s^2] (features, and the scale of J).
    tau_scale : float
        Torque scale [Nm] of the network output.
    play_widths : sequence of float
        Play-operator half-widths [rad].
    hidden : int
        LSTM hidden size.
    head : int
        Hidden tanh nodes of the read-out MLP.
    rigid : bool
        Co-identify J [kg m^2] and c [Nm].
    J, c : float
        Initial inertia [kg m^2] and offset [Nm].
    """

    # buffers (register_buffer), declared for the type checker
    v_scale: torch.Tensor
    a_scale: torch.Tensor
    tau_scale: torch.Tensor
    play_widths: torch.Tensor

    def __init__(self, v_scale: float, a_scale: float, tau_scale: float,
                 play_widths: tuple[float, ...] = DEFAULT_PLAY_WIDTHS, hidden: int = 16, head: int = 32,
                 rigid: bool = True, J: float = 0.0, c: float = 0.0):
        super().__init__()
        self.rigid = rigid
        dt = LSTM_DTYPE
        self.register_buffer("v_scale", torch.tensor(float(v_scale), dtype=torch.float64))
        self.register_buffer("a_scale", torch.tensor(float(a_scale), dtype=torch.float64))
        self.register_buffer("tau_scale", torch.tensor(float(tau_scale), dtype=dt))
        self.register_buffer("play_widths", torch.tensor([float(w) for w in play_widths], dtype=torch.float64))
        n_in = 4 + len(play_widths)
        self.lstm = nn.LSTM(n_in, hidden, batch_first=True, dtype=dt)
        self.head = nn.Sequential(nn.Linear(hidden + n_in, head, dtype=dt), nn.Tanh(), nn.Linear(head, 1, dtype=dt))
        # J and c in units of tau_scale/a_scale and tau_scale: order-1 parameters for Adam
        self.raw_J = nn.Parameter(torch.tensor(J * a_scale / tau_scale, dtype=dt), requires_grad=rigid)
        self.raw_c = nn.Parameter(torch.tensor(c / tau_scale, dtype=dt), requires_grad=rigid)

    @property
    def scales(self) -> FeatureScales:
        return FeatureScales(float(self.v_scale), float(self.a_scale), tuple(self.play_widths.tolist()))

    def forward(self, x: torch.Tensor, qdd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(friction, total) [Nm] for windows of features ``x`` (batch, time, features) and
        raw acceleration ``qdd`` [rad/s^2] (batch, time)."""
        h, _ = self.lstm(x)
        friction = self.tau_scale * self.head(torch.cat([h, x], dim=-1)).squeeze(-1)
        if not self.rigid:
            return friction, friction
        J = self.raw_J * self.tau_scale / float(self.a_scale)
        return friction, friction + J * qdd + self.raw_c * self.tau_scale

    def rigid_parameters(self) -> dict[str, float]:
        """Identified J [kg m^2] and c [Nm] (empty when the rigid-body torque was given)."""
        if not self.rigid:
            return {}
        with torch.no_grad():
            tau, a = float(self.tau_scale), float(self.a_scale)
            return {"J": float(self.raw_J) * tau / a, "c": float(self.raw_c) * tau}


@dataclass(frozen=True)
class WindowLayout:
    """How a record of ``n`` samples is cut into warm-up + scored windows (module docstring).

    Attributes
    ----------
    n : int
        Record length [samples].
    window : int
        Scored samples per window.
    warmup : int
        Unscored history samples before each window.
    index : ndarray of int, shape (windows, warmup + window)
        Record sample feeding each window position (clamped: padding repeats the first or
        last sample).
    scored : ndarray of bool, same shape
        True where the position is a real sample scored by this window.
    """

    n: int
    window: int
    warmup: int
    index: np.ndarray
    scored: np.ndarray

    @classmethod
    def of(cls, n: int, window: int, warmup: int) -> WindowLayout:
        count = max(1, -(-n // window))
        pos = np.arange(count)[:, None] * window + np.arange(warmup + window)[None, :] - warmup
        scored = (pos >= 0) & (pos < n)
        scored[:, :warmup] = False
        return cls(n=n, window=window, warmup=warmup, index=np.clip(pos, 0, max(n - 1, 0)), scored=scored)

    def gather(self, x: np.ndarray) -> torch.Tensor:
        """``x`` (n, ...) laid out as windows (windows, warmup + window, ...)."""
        return torch.as_tensor(np.ascontiguousarray(x[self.index]), dtype=LSTM_DTYPE)

    def scatter(self, y: np.ndarray) -> np.ndarray:
        """Per-window outputs (windows, warmup + window) back to one value per sample."""
        return np.asarray(y)[:, self.warmup:].reshape(-1)[:self.n]


def _linear_start(record: AxisRecord, v_scale: float) -> tuple[float, float]:
    """J [kg m^2] and c [Nm] of a least-squares fit ``mu*tanh(qd/v_t) + nu*qd + J*qdd + c``,
    the start of the co-identified rigid part (a generic regression, no friction model)."""
    qd, qdd = record.qd, record.qdd
    H = np.stack([np.tanh(qd / (TANH_VELOCITY * v_scale)), qd, qdd, np.ones_like(qd)], axis=-1)
    theta, *_ = np.linalg.lstsq(H, record.friction_target, rcond=None)
    return float(theta[2]), float(theta[3])


class LSTMFriction(FrictionModel):
    """Black-box LSTM friction baseline (see the module docstring).

    Parameters
    ----------
    hidden : int
        LSTM hidden size.
    head : int
        Hidden tanh nodes of the read-out MLP.
    window : int
        Scored samples per window.
    warmup : int
        History samples before each window [samples].
    epochs : int
        Passes over all windows.
    batches : int
        Adam steps per epoch (the windows split, once, into this many seeded batches).
    lr : float
        Initial learning rate (cosine decay to 2% of it).
    grad_clip : float
        Gradient-norm clip [-] (LSTMs occasionally produce gradient spikes).
    weight_decay : float
        AdamW weight decay [-].
    play_widths : sequence of float
        Play-operator half-widths [rad] of the features.
    seed : int
        Torch seed (initialisation, batch split, training).
    """

    name = "lstm"
    units = {"J": "kg m^2", "c": "Nm"}

    def __init__(self, hidden: int = 16, head: int = 32, window: int = 150, warmup: int = 150, epochs: int = 300,
                 batches: int = 4, lr: float = 0.01, grad_clip: float = 1.0, weight_decay: float = 0.0,
                 play_widths: tuple[float, ...] | list[float] = DEFAULT_PLAY_WIDTHS, seed: int = 0):
        self.hidden = hidden
        self.head = head
        self.window = window
        self.warmup = warmup
        self.epochs = epochs
        self.batches = batches
        self.lr = lr
        self.grad_clip = grad_clip
        self.weight_decay = weight_decay
        self.play_widths = [float(w) for w in play_widths]
        self.seed = seed

    def _check_hyperparameters(self) -> None:
        for key in ("hidden", "head", "window", "epochs", "batches"):
            if int(getattr(self, key)) < 1:
                raise InputError("must be >= 1", source="lstm hyperparameters", field=key)
        if self.warmup < 0:
            raise InputError("must be >= 0", source="lstm hyperparameters", field="warmup")
        if not self.play_widths or min(self.play_widths) <= 0:
            raise InputError("needs at least one width, all > 0 [rad]", source="lstm hyperparameters",
                             field="play_widths")

    def _inputs(self, record: AxisRecord, scales: FeatureScales) -> tuple[WindowLayout, torch.Tensor, torch.Tensor]:
        layout = WindowLayout.of(record.n, self.window, self.warmup)
        x = sequence_features(record.q, record.qd, record.qdd, scales)
        return layout, layout.gather(x), layout.gather(np.asarray(record.qdd, dtype=float))

    def _fit(self, record: AxisRecord) -> None:
        self._check_hyperparameters()
        with torch_threads(LSTM_THREADS):
            self._train(record)

    def _train(self, record: AxisRecord) -> None:
        rigid = bool(self.rigid_)
        scales = FeatureScales.from_record(record.qd, record.qdd, self.play_widths)
        J0, c0 = _linear_start(record, scales.v_scale) if rigid else (0.0, 0.0)
        rest = record.friction_target - (J0 * record.qdd + c0)
        tau_scale = float(np.std(rest)) or 1.0
        with deterministic(self.seed):
            net = LSTMFrictionNet(scales.v_scale, scales.a_scale, tau_scale, scales.play_widths, self.hidden,
                                  self.head, rigid=rigid, J=J0, c=c0)
            order = torch.randperm(-(-record.n // self.window))
        layout, x, qdd = self._inputs(record, scales)
        y = layout.gather(np.asarray(record.friction_target, dtype=float))
        mask = torch.as_tensor(layout.scored)
        batches = [(x[i], qdd[i], y[i], mask[i]) for i in order.tensor_split(min(self.batches, len(order)))]

        def loss_fn(module, batch):
            _, total = module(batch[0], batch[1])
            err = (total - batch[2]) / module.tau_scale
            return torch.mean(err[batch[3]] ** 2)

        self.history_: TrainingHistory = train(net, loss_fn, batches, epochs=self.epochs, lr=self.lr,
                                               seed=self.seed, lr_final=0.02, grad_clip=self.grad_clip,
                                               weight_decay=self.weight_decay)
        self.net_ = net
        self.params_ = net.rigid_parameters()

    def _friction(self, record: AxisRecord) -> np.ndarray:
        layout, x, qdd = self._inputs(record, self.net_.scales)
        with torch.no_grad(), torch_threads(LSTM_THREADS):
            friction, _ = self.net_(x, qdd)
        return layout.scatter(friction.numpy()).astype(float)

    def n_parameters(self) -> int:
        self._check_fitted()
        return count_parameters(self.net_)

    def _save_extra(self, directory: Path) -> None:
        torch.save({"format": NETWORK_FORMAT, "rigid": self.net_.rigid, "state": self.net_.state_dict()},
                   directory / NETWORK_FILE)

    def _load_extra(self, directory: Path) -> None:
        path = directory / NETWORK_FILE
        if not path.exists():
            raise InputError(f"LSTM model folder without {NETWORK_FILE}", source=str(directory))
        blob = torch.load(path, weights_only=True)
        if blob.get("format") != NETWORK_FORMAT:
            raise InputError(f"saved by an older LSTM version (network format {blob.get('format', 1)}, "
                             f"expected {NETWORK_FORMAT}): refit the model", source=str(path), field="format")
        st = blob["state"]
        net = LSTMFrictionNet(float(st["v_scale"]), float(st["a_scale"]), float(st["tau_scale"]),
                              tuple(st["play_widths"].tolist()), self.hidden, self.head, rigid=blob["rigid"])
        net.load_state_dict(st)
        net.eval()
        self.net_ = net
