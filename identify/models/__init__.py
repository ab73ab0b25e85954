"""Friction models with one estimator contract (:class:`~identify.models.base.FrictionModel`).

``MODELS`` maps the CLI names to the classes; :func:`load_model` opens a saved model folder.
"""
from __future__ import annotations

import os
from pathlib import Path

from identify.errors import InputError
from identify.models.base import FrictionModel, read_params
from identify.models.lugre import LuGre, LuGreTable
from identify.models.static import CoulombViscous, Stribeck
from identify.models.greybox import GreyBoxLuGre
from identify.models.lstm import LSTMFriction
from identify.models.residual import ResidualLuGre

MODELS: dict[str, type[FrictionModel]] = {
    CoulombViscous.name: CoulombViscous,
    Stribeck.name: Stribeck,
    LuGre.name: LuGre,
    LSTMFriction.name: LSTMFriction,
    ResidualLuGre.name: ResidualLuGre,
    GreyBoxLuGre.name: GreyBoxLuGre,
}


def register(cls: type[FrictionModel]) -> type[FrictionModel]:
    """Add a model class to :data:`MODELS` (used by the learned models)."""
    MODELS[cls.name] = cls
    return cls


def make_model(name: str, **hyperparameters) -> FrictionModel:
    """A new, unfitted model by its CLI name."""
    if name not in MODELS:
        raise InputError(f"unknown model '{name}' (known: {', '.join(MODELS)})", field="model")
    return MODELS[name](**hyperparameters)


def load_model(ref: str | os.PathLike) -> FrictionModel:
    """Load a fitted model from a saved folder (``params.json`` + model files), or from an MLflow
    model URI (``runs:/<run_id>/model``, ``models:/<name>@<alias>``, see :mod:`identify.tracking`)."""
    if str(ref).startswith(("runs:/", "models:/")):
        from identify.tracking import load_tracked_model  # lazy: tracking imports this module

        return load_tracked_model(str(ref))
    directory = Path(ref)
    doc = read_params(directory)
    name = doc["model"]
    if name not in MODELS:
        raise InputError(f"unknown model '{name}'", source=str(directory), field="model")
    return MODELS[name].from_document(doc, directory)


__all__ = ["MODELS", "FrictionModel", "LuGre", "LuGreTable", "CoulombViscous", "Stribeck", "GreyBoxLuGre",
           "ResidualLuGre", "LSTMFriction", "load_model",
           "make_model", "register"]

from identify.models.extended import LuGreExtended  # noqa: E402  (imports the helpers above)

register(LuGreExtended)
