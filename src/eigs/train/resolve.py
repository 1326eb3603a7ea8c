"""A run's options, checked in one place (no torch): what ``eigs train --config`` takes, the workflow's ``runs:``
entries (checked while Snakemake plans the DAG) and a method's own options all go through :func:`train_config`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from eigs.errors import EigsError
from eigs.train.catalog import method
from eigs.train.config import TrainConfig
from eigs.train.options import Options
from eigs.util.options import unknown_keys

RUN_KEYS = ["method", "bins", "options", "scenes"]  # the keys of a `runs:` entry (workflow/schemas)


def resolve_run(
    values: Mapping[str, Any], where: str = "train config", method_name: str | None = None, steps: int | None = None
) -> tuple[TrainConfig, Options]:
    """A run's :class:`TrainConfig` and its method's parsed options (:func:`train_config`), parsed once: ``eigs
    train`` hands both to the trainer, which hands the options to the method."""
    cfg = _config(values, where, method_name, steps)
    return cfg, method_options(cfg, where)


def train_config(
    values: Mapping[str, Any], where: str = "train config", method_name: str | None = None, steps: int | None = None
) -> TrainConfig:
    """The :class:`TrainConfig` of ``values`` (the ``--config`` JSON: TrainConfig's keys) with ``method_name`` and
    ``steps`` (the command line's ``--method`` and ``--steps``) over them; without a step count from either, the
    method's own default budget (:attr:`eigs.train.catalog.MethodSpec.steps`). Checks the keys, types and ranges,
    the method and its ``method_options``."""
    return resolve_run(values, where, method_name, steps)[0]


def _config(values: Mapping[str, Any], where: str, method_name: str | None, steps: int | None) -> TrainConfig:
    cfg = TrainConfig.from_dict(dict(values), where)
    spec = method(method_name or cfg.method, where)
    resolved = {**cfg.to_dict(), "method": spec.name}
    if steps is not None:
        resolved["steps"] = int(steps)
    elif "steps" not in values:
        resolved["steps"] = spec.steps
    return TrainConfig.from_dict(resolved, "command line" if method_name is not None or steps is not None else where)


def method_options(cfg: TrainConfig, where: str | None = None) -> Options:
    """The options of ``cfg.method``: its recipe with ``cfg.method_options`` over it, checked."""
    spec = method(cfg.method)
    return spec.parse(cfg.method_options, f"{where}: method_options ({spec.name})" if where else None)


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
