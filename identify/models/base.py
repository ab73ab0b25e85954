"""The estimator contract shared by every friction model.

As in pysindy/scikit-learn: ``__init__`` stores hyperparameters only; ``fit`` returns self;
fitted state ends in ``_``; predicting or saving before fitting raises
:class:`~identify.errors.NotFittedError`; ``save``/``load`` round-trip exactly.

Every model predicts the *total* torque of a record, like the measurement it is fitted to::

    tau_pred = tau_F(qd, ...) + J*qdd + c        (no tau_rb in the training record)
    tau_pred = tau_F(qd, ...) + tau_rb           (tau_rb given: rigid body known)

so the inertia J [kg m^2] and offset c [Nm] are co-identified with the friction (as in
IDIM-LS) unless the rigid-body torque is known.
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from identify.errors import InputError, NotFittedError
from identify.files import as_created
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

    # ---- hyperparameters -------------------------------------------------------------
    def get_hyperparameters(self) -> dict[str, Any]:
        """Constructor arguments (everything set in ``__init__``)."""
        return {k: v for k, v in vars(self).items() if not k.endswith("_") and not k.startswith("_")}

    # ---- fitting ---------------------------------------------------------------------
    def fit(self, record: AxisRecord) -> "FrictionModel":
        """Identify the model on a training record; returns self."""
        self.rigid_ = record.tau_rb is None
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

    def predict(self, record: AxisRecord) -> np.ndarray:
        """Total joint torque [Nm] per sample, comparable to the record's ``tau``."""
        return self.predict_friction(record) + self.rigid_part(record)

    def score(self, record: AxisRecord) -> Metrics:
        return evaluate(record.tau, self.predict(record))

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
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
        as_created(tmp, directory=True)
        try:
            doc = {
                "model": self.name,
                "format": FORMAT_VERSION,
                "rigid": bool(self.rigid_),
                "hyperparameters": self.get_hyperparameters(),
                "params": {k: {"value": float(v), "unit": self.units.get(k, "")} for k, v in self.params_.items()},
                "train_metrics": self.train_metrics_.to_dict() if hasattr(self, "train_metrics_") else None,
            }
            (tmp / PARAMS_FILE).write_text(json.dumps(doc, indent=2) + "\n")
            self._save_extra(tmp)
            if target.exists():
                shutil.rmtree(target)
            os.replace(tmp, target)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp)
        return target

    def _save_extra(self, directory: Path) -> None:
        pass

    def _load_extra(self, directory: Path) -> None:
        pass

    @classmethod
    def from_document(cls, doc: dict, directory: Path) -> "FrictionModel":
        model = cls(**doc.get("hyperparameters", {}))
        model.rigid_ = bool(doc["rigid"])
        model.params_ = {k: float(v["value"]) for k, v in doc["params"].items()}
        if doc.get("train_metrics"):
            model.train_metrics_ = Metrics(**doc["train_metrics"])
        model._load_extra(directory)
        return model

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "FrictionModel":
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
