"""The estimator contract shared by every friction model.

As in pysindy/scikit-learn: ``__init__`` stores hyperparameters only; ``fit`` returns self;
fitted state ends in ``_``; predicting or saving before fitting raises
:class:`~identify.errors.NotFittedError`; ``save``/``load`` round-trip exactly.

The rigid-body torque contract, the same for every model type:

- a record *with* ``tau_rb`` [Nm]: the model learns the friction ``tau - tau_rb``
  (:attr:`~identify.records.AxisRecord.friction_target`) and nothing rigid, apart from a
  constant offset c [Nm] of the torque reading (a sensor bias no rigid-body model holds; on
  real arms it is of the order of the friction itself), which it reports as ``c`` and
  predicts as part of ``tau_friction_pred``;
- a record *without* it: the model learns ``tau`` and co-identifies an inertia J [kg m^2] and
  an offset c [Nm] with the friction (as in IDIM-LS).

Predictions come in two parts (:meth:`FrictionModel.predict_parts`): the friction
``tau_friction_pred`` = tau_F(qd, ...) and the total joint torque, comparable to ``tau``::

    tau_pred = tau_friction_pred + tau_rb          (fitted with tau_rb)
    tau_pred = tau_friction_pred + J*qdd + c       (fitted without)

``tau_rb`` is never subtracted twice: a model composed of others (the residual model) trains
its parts on :meth:`FrictionModel.target_part`, the share of ``friction_target`` a part
explains, never on the total.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, ClassVar, Self

import numpy as np

from identify.errors import InputError, NotFittedError
from identify.files import atomic_folder
from identify.metrics import Metrics, evaluate
from identify.records import AxisRecord

PARAMS_FILE = "params.json"
FORMAT_VERSION = 1


class FrictionModel:
    """Base class of the friction estimators.

    Subclasses set ``name`` and ``units`` (parameter -> unit), implement ``_fit`` and
    ``_friction``, and, when they hold more than scalar parameters, ``_save_extra`` and
    ``_load_extra``.
    """

    name: ClassVar[str] = "base"
    #: Units of the fitted parameters, for the human-readable params file.
    units: ClassVar[dict[str, str]] = {}
    # fitted state, set by fit() or a load (declared for the type checker; absent until then)
    params_: dict[str, float]
    rigid_: bool
    linear_: bool
    cutoff_hz_: float | None
    train_metrics_: Metrics

    # ---- hyperparameters -------------------------------------------------------------
    def get_hyperparameters(self) -> dict[str, Any]:
        """Constructor arguments (everything set in ``__init__``)."""
        return {k: v for k, v in vars(self).items() if not k.endswith("_") and not k.startswith("_")}

    # ---- fitting ---------------------------------------------------------------------
    def fit(self, record: AxisRecord) -> Self:
        """Identify the model on a training record; returns self."""
        self.rigid_ = record.tau_rb is None
        self.linear_ = bool(record.linear)
        self.cutoff_hz_ = record.cutoff_hz
        self._fit(record)
        self.train_metrics_ = self.score(record)
        return self

    def _fit(self, record: AxisRecord) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _friction(self, record: AxisRecord) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def _check_fitted(self) -> None:
        if not hasattr(self, "params_"):
            raise NotFittedError(f"{type(self).__name__} is not fitted: call fit() first (or load a saved model)")

    # ---- prediction ------------------------------------------------------------------
    def predict_friction(self, record: AxisRecord) -> np.ndarray:
        """Friction torque tau_F [Nm] per sample."""
        self._check_fitted()
        return self._friction(record)

    def rigid_part(self, record: AxisRecord) -> np.ndarray:
        """The non-friction torque the model adds: J*qdd + c, or tau_rb [Nm]."""
        self._check_fitted()
        if self.rigid_:
            return self.params_["J"] * record.qdd + self.params_["c"]
        if record.tau_rb is None:
            raise InputError("the model was fitted with a known rigid-body torque: this record needs a 'tau_rb' column",
                             source=record.source, field="tau_rb")
        return record.tau_rb

    def offset(self) -> float:
        """The co-identified torque offset c [Nm] that belongs to the friction prediction: when
        the model was fitted with ``tau_rb`` (without, c is part of :meth:`rigid_part`)."""
        self._check_fitted()
        return 0.0 if self.rigid_ else float(self.params_.get("c", 0.0))

    def target_part(self, record: AxisRecord) -> np.ndarray:
        """The model's prediction of ``record.friction_target`` [Nm]: the friction, plus J*qdd + c
        when co-identified (never plus ``tau_rb``, which the target has already left out)."""
        _, total = self.predict_parts(record)
        return total if self.rigid_ else total - record.tau_rb

    def predict_parts(self, record: AxisRecord) -> tuple[np.ndarray, np.ndarray]:
        """``(tau_friction_pred, tau_pred)`` [Nm] per sample: the friction, and the total joint
        torque ``tau_friction_pred + tau_rb`` (or ``+ J*qdd + c``), see the module docstring."""
        friction = self.predict_friction(record)
        total = friction + self.rigid_part(record)
        if not self.rigid_:  # everything learned of tau - tau_rb (extensions' corrections too)
            friction = total - record.tau_rb
        return friction, total

    def predict(self, record: AxisRecord) -> np.ndarray:
        """Total joint torque [Nm] per sample, comparable to the record's ``tau``."""
        return self.predict_parts(record)[1]

    def score(self, record: AxisRecord) -> Metrics:
        return evaluate(record.tau, self.predict(record))

    def param_units(self) -> dict[str, str]:
        """Units of the fitted parameters, for this model's axis kind (rotary: :attr:`units`;
        linear: m for rad, N for Nm, kg for kg m^2)."""
        from identify.records import linear_unit

        if getattr(self, "linear_", False):
            return {k: linear_unit(u) for k, u in self.units.items()}
        return dict(self.units)

    def n_parameters(self) -> int:
        """Number of identified scalars (parameters and network weights)."""
        self._check_fitted()
        return len(self.params_)

    # ---- persistence -----------------------------------------------------------------
    def save(self, directory: str | os.PathLike) -> Path:
        """Write ``params.json`` (human-readable, with units) plus model-specific files.

        Written to a temporary folder and renamed into place, so a failure leaves nothing
        half-written.
        """
        self._check_fitted()
        target = Path(directory)
        with atomic_folder(target) as tmp:
            doc = {
                "model": self.name,
                "format": FORMAT_VERSION,
                "rigid": bool(self.rigid_),
                "linear": bool(getattr(self, "linear_", False)),
                "derivative_cutoff_hz": getattr(self, "cutoff_hz_", None),
                "hyperparameters": self.get_hyperparameters(),
                "params": {k: {"value": float(v), "unit": self.param_units().get(k, "")}
                           for k, v in self.params_.items()},
                "train_metrics": self.train_metrics_.to_dict() if hasattr(self, "train_metrics_") else None,
            }
            (tmp / PARAMS_FILE).write_text(json.dumps(doc, indent=2) + "\n")
            self._save_extra(tmp)
        return target

    def _save_extra(self, directory: Path) -> None:
        pass

    def _load_extra(self, directory: Path) -> None:
        pass

    @classmethod
    def from_document(cls, doc: dict, directory: Path) -> Self:
        model = cls(**doc.get("hyperparameters", {}))
        model.rigid_ = bool(doc["rigid"])
        model.linear_ = bool(doc.get("linear", False))
        cut = doc.get("derivative_cutoff_hz")
        model.cutoff_hz_ = None if cut is None else float(cut)
        model.params_ = {k: float(v["value"]) for k, v in doc["params"].items()}
        if doc.get("train_metrics"):
            model.train_metrics_ = Metrics(**doc["train_metrics"])
        model._load_extra(directory)
        return model

    @classmethod
    def load(cls, directory: str | os.PathLike) -> Self:
        doc = read_params(directory)
        if doc["model"] != cls.name:
            raise InputError(f"holds a '{doc['model']}' model, not '{cls.name}'", source=str(directory), field="model")
        return cls.from_document(doc, Path(directory))


def read_params(directory: str | os.PathLike) -> dict:
    """The parsed ``params.json`` of a saved model folder, with errors naming the file."""
    p = Path(directory) / PARAMS_FILE
    if not p.exists():
        raise InputError(f"not a saved model folder (no {PARAMS_FILE})", source=str(directory))
    try:
        doc = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc}", source=str(p)) from None
    for key in ("model", "rigid", "params"):
        if key not in doc:
            raise InputError("missing key", source=str(p), field=key)
    return doc
