"""Training of the learned friction models: a thin LightningModule around a plain ``nn.Module``.

The physics lives in ordinary ``torch.nn.Module`` classes (:mod:`identify.models.greybox`,
:mod:`identify.models.residual`, :mod:`identify.models.lstm`); this module only holds the
optimisation step (Adam with a cosine-decaying learning rate, paper 2.3.1: gradient descent
with Adam) and runs it with a quiet Lightning ``Trainer`` on the CPU: no progress bar, no
logger, no checkpoints. The per-epoch loss is returned in a :class:`TrainingHistory` so the
caller decides where it goes (MLflow, :mod:`identify.tracking`).

Determinism: the seed is applied with ``torch.manual_seed`` before the network is built and
again before training, and ``torch.use_deterministic_algorithms(True)`` is in force while
training (restored afterwards).
"""
from __future__ import annotations

import contextlib
import logging
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Literal

import torch

#: Floating-point type of the physics-based learned models: the bristle scan and the stiff
#: exponentials want float64, and records are short enough that it costs little. (The
#: black-box LSTM runs in float32, see :mod:`identify.models.lstm`; :func:`train` follows the
#: network's type.)
DTYPE = torch.float64


@dataclass
class TrainingHistory:
    """What one training run did.

    Attributes
    ----------
    loss : list of float
        Mean training loss per epoch (normalised squared error, -).
    seconds : float
        Wall time of the training loop [s].
    """

    loss: list[float] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def epochs(self) -> int:
        return len(self.loss)


@contextlib.contextmanager
def deterministic(seed: int) -> Iterator[None]:
    """Seed torch and enforce deterministic algorithms inside the block (CPU)."""
    previous = torch.are_deterministic_algorithms_enabled()
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(previous)


@contextlib.contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run the block with ``n`` torch intra-op threads, restoring the previous count after.

    For small recurrent nets whose per-step operations are too small to share out: extra
    threads only add synchronisation (on a loaded 2-core machine an LSTM fit ran several
    times slower with two threads than with one), and a fixed count makes the result the
    same whichever thread count the caller runs with.
    """
    previous = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _quiet_lightning() -> None:
    for name in ("lightning", "lightning.pytorch", "lightning.fabric", "pytorch_lightning"):
        logging.getLogger(name).setLevel(logging.ERROR)
    warnings.filterwarnings("ignore", message=".*does not have many workers.*")
    warnings.filterwarnings("ignore", message=".*LightningModule.*")
    warnings.filterwarnings("ignore", message=".*num_workers.*")
    warnings.filterwarnings("ignore", message=".*treespec.*")


LossFn = Callable[[torch.nn.Module, tuple], torch.Tensor]


def train(net: torch.nn.Module, loss_fn: LossFn, batches: Sequence[tuple], *, epochs: int, lr: float,
          seed: int = 0, lr_final: float = 0.05, grad_clip: float | None = None, weight_decay: float = 0.0,
          on_epoch: Callable[[int, float], None] | None = None) -> TrainingHistory:
    """Train ``net`` with Adam on ``batches`` for ``epochs`` passes, via a Lightning Trainer.

    Parameters
    ----------
    net : torch.nn.Module
        The model; trained in place.
    loss_fn : callable
        ``loss_fn(net, batch) -> scalar tensor``.
    batches : sequence of tuple
        The batches of one epoch (a full record is one batch), in fixed order.
    epochs : int
        Passes over ``batches``.
    lr : float
        Initial learning rate of Adam [-], decayed by a cosine schedule to ``lr*lr_final``.
    seed : int
        Torch seed.
    lr_final : float
        Final learning rate as a share of ``lr`` [-].
    grad_clip : float, optional
        Clip the gradient norm to this value [-] (recurrent nets); no clipping when None.
    weight_decay : float
        Decoupled weight decay of AdamW on the weight matrices [-] (0: plain Adam).
    on_epoch : callable, optional
        Called with (epoch, mean loss) after each epoch.
    """
    import lightning.pytorch as pl

    _quiet_lightning()

    class _Step(pl.LightningModule):
        def __init__(self):
            super().__init__()
            self.net = net
            self._epoch_losses: list[float] = []

        def training_step(self, batch, batch_idx):
            loss = loss_fn(self.net, batch)
            self._epoch_losses.append(float(loss.detach()))
            return loss

        def on_train_epoch_end(self):
            mean = sum(self._epoch_losses) / max(len(self._epoch_losses), 1)
            self._epoch_losses.clear()
            history.loss.append(mean)
            if on_epoch is not None:
                on_epoch(len(history.loss), mean)

        def configure_optimizers(self):
            if weight_decay > 0:
                # decay weight matrices only: biases and physical scalars (J, c, s0, ...) keep their values
                params = list(self.net.parameters())
                groups = [{"params": [p for p in params if p.ndim >= 2], "weight_decay": weight_decay},
                          {"params": [p for p in params if p.ndim < 2], "weight_decay": 0.0}]
                opt = torch.optim.AdamW(groups, lr=lr)
            else:
                opt = torch.optim.Adam(self.net.parameters(), lr=lr)
            total = max(1, epochs * len(batches))
            sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=total, eta_min=lr * lr_final)
            return {"optimizer": opt, "lr_scheduler": {"scheduler": sched, "interval": "step"}}

    class _Batches(torch.utils.data.Dataset):
        def __len__(self):
            return len(batches)

        def __getitem__(self, i):
            return batches[i]

    history = TrainingHistory()
    loader = torch.utils.data.DataLoader(_Batches(), batch_size=None, shuffle=False, num_workers=0)
    # the network's own floating-point type decides the precision ("64-true" would cast a float32 net)
    wide = any(p.dtype == torch.float64 for p in net.parameters())
    precision: Literal["64-true", "32-true"] = "64-true" if wide else "32-true"
    trainer = pl.Trainer(max_epochs=epochs, accelerator="cpu", devices=1, logger=False, enable_progress_bar=False,
                         enable_checkpointing=False, enable_model_summary=False, deterministic=True,
                         num_sanity_val_steps=0, precision=precision, gradient_clip_val=grad_clip,
                         gradient_clip_algorithm="norm")
    net.train()  # a net fitted before was left in eval mode
    with deterministic(seed):
        t0 = time.perf_counter()
        trainer.fit(_Step(), train_dataloaders=loader)
        history.seconds = time.perf_counter() - t0
    net.eval()
    return history


def count_parameters(net: torch.nn.Module) -> int:
    """Number of trainable scalars of a network."""
    return int(sum(p.numel() for p in net.parameters() if p.requires_grad))
