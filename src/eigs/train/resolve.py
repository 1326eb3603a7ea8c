"""A run resolved in one place (no torch at import): its :class:`TrainConfig`, its method's options parsed once into
the method's frozen options dataclass, and the method built from its catalog entry with them. What ``eigs train
--config`` takes and the workflow's ``runs:`` entries (checked while Snakemake plans the DAG) both go through
:func:`resolve_run`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from eigs.errors import EigsError
from eigs.train.catalog import GAUSSIAN, method, method_class
from eigs.train.config import TrainConfig
from eigs.util.options import Options, parse_options, unknown_keys

if TYPE_CHECKING:
    import torch

    from eigs.train.data import TrainData

RUN_KEYS = ["method", "bins", "options", "scenes"]  # the keys of a `runs:` entry (workflow/schemas)


def resolve_run(
    values: Mapping[str, Any], where: str = "train config", method_name: str | None = None, steps: int | None = None
) -> tuple[TrainConfig, Options]:
    """The :class:`TrainConfig` of ``values`` (the ``--config`` JSON: TrainConfig's keys) with ``method_name`` and
    ``steps`` (the command line's ``--method`` and ``--steps``) over them, and its method's options: the method's
    recipe (:mod:`eigs.train.catalog`) with ``method_options`` over it, parsed once into its options dataclass.
    Without a step count from either, the method's own default budget (:attr:`~eigs.train.catalog.MethodSpec.steps`).
    Any error is one :class:`EigsError` line naming the key."""
    cfg = TrainConfig.from_dict(values, where)
    spec = method(method_name or cfg.method, where)
    resolved = {**cfg.to_dict(), "method": spec.name}
    if steps is not None:
        resolved["steps"] = int(steps)
    elif "steps" not in values:
        resolved["steps"] = spec.steps
    cfg = TrainConfig.from_dict(resolved, "command line" if method_name is not None or steps is not None else where)
    if cfg.camera_refine and spec.family != GAUSSIAN:
        raise EigsError(where, f"camera_refine: method {spec.name} is a {spec.family} method; camera refinement is for "
                               f"the {GAUSSIAN} methods")  # fmt: skip
    return cfg, parse_options(spec.defaults(), cfg.method_options, f"{where}: method_options ({spec.name})")


def train_config(
    values: Mapping[str, Any], where: str = "train config", method_name: str | None = None, steps: int | None = None
) -> TrainConfig:
    """The :class:`TrainConfig` of :func:`resolve_run` (its method options checked too)."""
    return resolve_run(values, where, method_name, steps)[0]


def method_options(cfg: TrainConfig) -> Options:
    """The options of a resolved ``cfg.method``: its recipe with ``cfg.method_options`` over it, checked."""
    spec = method(cfg.method)
    return parse_options(spec.defaults(), cfg.method_options, f"method {spec.name}")


def warn_without_events(method_name: str, reads_events: bool, data: TrainData) -> None:
    """Log a warning when a method that reads events trains on an EDI artifact without any (a scene without events,
    or ``eigs edi --no-events``: every latent frame is the blurry frame; the workflow does not schedule such runs)."""
    import logging

    import numpy as np

    if reads_events and not np.asarray(data.edi.event_count).any():
        logging.getLogger("eigs.train").warning(
            "method %s reads events, but the EDI artifact of %s has none (every view passed through as sharp): "
            "it trains on the blurry frames only", method_name, data.scene.name,
        )  # fmt: skip


def build_method(
    base: type, data: TrainData, cfg: TrainConfig, device: torch.device, options: Options | None = None
) -> Any:
    """The method ``cfg.method``, a ``base`` subclass (its family's method base), ready to train on ``data`` with
    ``options`` (its parsed options from :func:`resolve_run`; parsed from ``cfg`` here when a caller has none)."""
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


def check_run(run: str, spec: Any) -> TrainConfig:
    """A workflow ``runs:`` entry as the train job will resolve it (``{"method": …, **options}``); any error is
    one :class:`EigsError` line naming the run, the key and the accepted keys."""
    where = f"config: run {run}"
    if not isinstance(spec, Mapping):
        raise EigsError(where, f"expected a mapping with {', '.join(RUN_KEYS)}, got {spec!r}")
    unknown_keys(spec, RUN_KEYS, where, "key")
    options = spec.get("options", {})
    if not isinstance(options, Mapping):
        raise EigsError(f"{where}: options", f"expected a mapping of training options, got {options!r}")
    return train_config({"method": spec.get("method"), **options}, f"{where}: options")


def check_runs(runs: Mapping[str, Any] | None) -> None:
    """:func:`check_run` for every entry of the config's ``runs:`` section."""
    for run, spec in (runs or {}).items():
        check_run(run, spec)
