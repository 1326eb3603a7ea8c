"""A training run's folder (``results/<scene>/b{B}/<run>/``), the one place its layout is spelled: the model file
(``model.ply``, a Gaussian cloud, :mod:`eigs.artifacts.gaussians`; or ``model.npz``, a radiance field,
:mod:`eigs.artifacts.field`), ``config.json`` (sections ``train``, ``inputs``, ``run``), ``train_log.csv`` (one row
per logged step), ``motion.npz`` (:mod:`eigs.artifacts.motion`) for methods that model motion within the exposure,
``cameras.npz`` (:mod:`eigs.artifacts.cameras`) for runs that refined their cameras, and the checkpoints in the
sibling ``<run>.partial/``. Training writes it (:mod:`eigs.train.loop`); evaluation, ``eigs render``, the tables,
the viewer, the rules and the bench tools read it through these names."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from eigs.errors import EigsError

MODEL_PLY = "model.ply"  # a Gaussian run's model
MODEL_NPZ = "model.npz"  # a radiance-field run's model
MODEL_FILES = (MODEL_PLY, MODEL_NPZ)  # one of them marks a finished run folder
CONFIG = "config.json"
LOG = "train_log.csv"
MOTION = "motion.npz"
CAMERAS = "cameras.npz"  # the refined training cameras (TrainConfig.camera_refine)
CHECKPOINT = "checkpoint.pt"  # in the partial folder


def workflow_scene(run_dir: str | Path) -> str | None:
    """The workflow's name of the scene a run folder was trained on: ``<scene>`` of ``…/<scene>/b<B>/<run>`` (the
    workflow's layout), None for a folder laid out otherwise. It can differ from the scene file's own name
    (``e2b-blocks`` is the built-in ``blocks`` made another way)."""
    parent = Path(run_dir).parent
    b = parent.name
    return parent.parent.name if len(b) > 1 and b[0] == "b" and b[1:].isdigit() and parent.parent.name else None


def partial_dir(run_dir: str | Path) -> Path:
    """The checkpoint folder of ``run_dir``: its sibling ``RUN_DIR.partial``."""
    run_dir = Path(run_dir)
    return run_dir.with_name(run_dir.name + ".partial")


def model_path(run_dir: str | Path) -> Path | None:
    """The model file of a finished run folder (``model.npz`` before ``model.ply``, as evaluation reads it), or None
    when it has neither."""
    for name in (MODEL_NPZ, MODEL_PLY):
        if (Path(run_dir) / name).is_file():
            return Path(run_dir) / name
    return None


def read_config(run_dir: str | Path) -> dict[str, Any]:
    """``config.json`` of a finished run folder; :class:`EigsError` naming it when it is missing or unreadable."""
    path = Path(run_dir) / CONFIG
    if not path.is_file():
        raise EigsError(run_dir, f"no {CONFIG} (not a finished run folder; run `eigs train` first)")
    try:
        return json.loads(path.read_text())
    except ValueError as err:
        raise EigsError(path, f"unreadable run config ({err})") from None
