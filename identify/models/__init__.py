"""Friction models with one estimator contract (:class:`~identify.models.base.FrictionModel`).

``MODELS`` maps the CLI names to the classes; :func:`load_model` opens a saved model folder
(:func:`identify.tracking.load_any_model` also opens MLflow model URIs). The learned models
(``lstm``, ``residual``, ``greybox``) need torch: their modules are imported when their class is
first asked for, so listing the model names, or using a static or LuGre model, loads no torch.
"""
from __future__ import annotations

import importlib
import os
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from identify.errors import InputError
from identify.models.base import FrictionModel, read_params
from identify.models.extended import LuGreExtended
from identify.models.lugre import LuGre, LuGreTable
from identify.models.static import CoulombViscous, Stribeck

if TYPE_CHECKING:
    from identify.models.greybox import GreyBoxLuGre
    from identify.models.lstm import LSTMFriction
    from identify.models.residual import ResidualLuGre

#: Learned model classes by attribute name: (module, CLI name), imported on first use.
_LEARNED = {"LSTMFriction": ("identify.models.lstm", "lstm"),
            "ResidualLuGre": ("identify.models.residual", "residual"),
            "GreyBoxLuGre": ("identify.models.greybox", "greybox")}


class ModelRegistry(Mapping[str, type[FrictionModel]]):
    """Model classes by CLI name, in registration order; a class given as ``(module, attribute)`` is
    imported when it is first looked up."""

    def __init__(self) -> None:
        self._entries: dict[str, type[FrictionModel] | tuple[str, str]] = {}

    def add(self, name: str, cls: type[FrictionModel] | tuple[str, str]) -> None:
        self._entries[name] = cls

    def __getitem__(self, name: str) -> type[FrictionModel]:
        entry = self._entries[name]
        if isinstance(entry, tuple):
            entry = getattr(importlib.import_module(entry[0]), entry[1])
            self._entries[name] = entry
        return entry

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)


MODELS = ModelRegistry()
MODELS.add(CoulombViscous.name, CoulombViscous)
MODELS.add(Stribeck.name, Stribeck)
MODELS.add(LuGre.name, LuGre)
for _attr, (_module, _name) in _LEARNED.items():
    MODELS.add(_name, (_module, _attr))
MODELS.add(LuGreExtended.name, LuGreExtended)


def __getattr__(attr: str) -> Any:
    """``from identify.models import GreyBoxLuGre`` (and the other learned models) imports torch only then."""
    if attr in _LEARNED:
        return MODELS[_LEARNED[attr][1]]
    raise AttributeError(f"module {__name__!r} has no attribute {attr!r}")


def register(cls: type[FrictionModel]) -> type[FrictionModel]:
    """Add a model class to :data:`MODELS`."""
    MODELS.add(cls.name, cls)
    return cls


def make_model(name: str, **hyperparameters: Any) -> FrictionModel:
    """A new, unfitted model by its CLI name."""
    if name not in MODELS:
        raise InputError(f"unknown model '{name}' (known: {', '.join(MODELS)})", field="model")
    return MODELS[name](**hyperparameters)


def parse_model_names(text: str | None, default: tuple[str, ...], field: str) -> list[str]:
    """Model names from a comma-separated list (``default`` when empty): each known, none twice;
    ``InputError`` naming ``field`` otherwise."""
    if not text:
        return list(default)
    names = [m.strip() for m in text.split(",") if m.strip()]
    if not names:
        raise InputError("no model named", field=field)
    for m in names:
        if m not in MODELS:
            raise InputError(f"unknown model '{m}' (known: {', '.join(MODELS)})", field=field)
    if len(set(names)) != len(names):
        raise InputError("a model is named twice", field=field)
    return names


def make_seeded(model: str, seed: int, epochs: int | None, *, model_field: str = "model",
                epochs_field: str = "epochs") -> FrictionModel:
    """A new model by name with its ``seed`` and, when it trains by epochs, ``epochs`` [passes] (the
    model's default when None); ``InputError`` naming ``model_field`` / ``epochs_field``."""
    if model not in MODELS:
        raise InputError(f"unknown model '{model}' (known: {', '.join(MODELS)})", field=model_field)
    hp = MODELS[model]().get_hyperparameters()
    kwargs: dict[str, Any] = {}
    if "seed" in hp:
        kwargs["seed"] = seed
    if epochs is not None:
        if epochs < 1:
            raise InputError("must be >= 1", field=epochs_field)
        if "epochs" in hp:
            kwargs["epochs"] = epochs
    return make_model(model, **kwargs)


def load_model(ref: str | os.PathLike) -> FrictionModel:
    """Load a fitted model from a saved folder (``params.json`` + model files). MLflow model URIs
    (``runs:/<run_id>/model``, ``models:/<name>@<alias>``) are opened by
    :func:`identify.tracking.load_any_model`."""
    if str(ref).startswith(("runs:/", "models:/")):
        raise InputError("an MLflow model URI: open it with identify.tracking.load_any_model", source=str(ref))
    directory = Path(ref)
    doc = read_params(directory)
    name = doc["model"]
    if name not in MODELS:
        raise InputError(f"unknown model '{name}'", source=str(directory), field="model")
    return MODELS[name].from_document(doc, directory)


__all__ = ["MODELS", "FrictionModel", "LuGre", "LuGreTable", "LuGreExtended", "CoulombViscous", "Stribeck",
           "GreyBoxLuGre", "ResidualLuGre", "LSTMFriction", "ModelRegistry", "load_model", "make_model",
           "make_seeded", "parse_model_names", "register"]
