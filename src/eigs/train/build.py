"""A run's method, built from its catalog entry (:mod:`eigs.train.catalog`): the class its ``plugin`` names, checked
against its family and what the run's data has, given the run's parsed options (parsed once, where the run is
resolved: :func:`eigs.train.resolve.resolve_run`)."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import torch

from eigs.errors import EigsError
from eigs.train.catalog import method, method_class
from eigs.train.config import TrainConfig
from eigs.train.data import TrainData
from eigs.train.options import Options
from eigs.train.resolve import method_options


def warn_without_events(method: str, reads_events: bool, data: TrainData) -> None:
    """Log a warning when a method that reads events trains on an EDI artifact without any (a scene without events,
    or ``eigs edi --no-events``: every latent frame is the blurry frame; the workflow does not schedule such runs)."""
    if reads_events and not np.asarray(data.edi.event_count).any():
        logging.getLogger("eigs.train").warning(
            "method %s reads events, but the EDI artifact of %s has none (every view passed through as sharp): "
            "it trains on the blurry frames only", method, data.scene.name,
        )  # fmt: skip


def build_method(
    base: type, data: TrainData, cfg: TrainConfig, device: torch.device, options: Options | None = None
) -> Any:
    """The method ``cfg.method``, a ``base`` subclass (its family's method base), ready to train on ``data`` with
    ``options`` (its parsed method options; parsed from ``cfg`` here only when a caller has none)."""
    spec = method(cfg.method)
    family = getattr(base, "family", None)
    if spec.family != family:
        raise EigsError("train", f"method {spec.name} is a {spec.family} method, not a {family} one")
    cls = method_class(spec.name)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise EigsError("train", f"method {spec.name}: {spec.plugin} is not a {base.__name__} subclass")
    if spec.needs_ground_truth and data.sharp_train is None:
        raise EigsError(data.scene.name, f"method {spec.name} needs ground-truth sharp images of the training views")
    warn_without_events(spec.name, spec.needs_events, data)
    return cls(data, cfg, options if options is not None else method_options(cfg), device)
