"""The method of a run, from its catalog entry (:mod:`eigs.train.catalog`): the class its ``plugin`` names, checked
against what the run's data has. The only place the method modules are imported by name."""

from __future__ import annotations

from typing import Any

import torch

from eigs.errors import EigsError
from eigs.train.catalog import FIELD, GAUSSIAN, method, method_class
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.field_methods import FieldMethod
from eigs.train.methods import Method, warn_without_events


def _make(base: type, family: str, data: TrainData, cfg: TrainConfig, device: torch.device) -> Any:
    spec = method(cfg.method)
    if spec.family != family:
        raise EigsError("train", f"method {spec.name} is a {spec.family} method, not a {family} one")
    cls = method_class(spec.name)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise EigsError("train", f"method {spec.name}: {spec.plugin} is not a {base.__name__} subclass")
    if spec.needs_ground_truth and data.sharp_train is None:
        raise EigsError(data.scene.name, f"method {spec.name} needs ground-truth sharp images of the training views")
    warn_without_events(spec.name, spec.needs_events, data)
    return cls(data, cfg, device)


def make_method(data: TrainData, cfg: TrainConfig, device: torch.device) -> Method:
    """The Gaussian method ``cfg.method``, ready to train on ``data``."""
    return _make(Method, GAUSSIAN, data, cfg, device)


def make_field_method(data: TrainData, cfg: TrainConfig, device: torch.device) -> FieldMethod:
    """The radiance-field method ``cfg.method``, ready to train on ``data``."""
    return _make(FieldMethod, FIELD, data, cfg, device)
