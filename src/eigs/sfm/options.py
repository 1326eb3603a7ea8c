"""Options of the ``sfm`` stage: :class:`SfmConfig` (with :class:`ColmapOptions`) holds every default; the config
schema, the rules and the CLI take theirs from here (see ``eigs.util.options``). No heavy imports: the CLI reads it
for its help text."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from eigs.errors import EigsError

MODES = ("auto", "colmap", "given", "model")
MATCHERS = ("auto", "exhaustive", "sequential")
DEVICES = ("auto", "cpu", "cuda")
CONFIG = {"config": True}  # field metadata: a key of the config's `sfm:` section (the COLMAP options sit beside the
# stage's own there); the others are run control or internal


@dataclass
class ColmapOptions:
    """Options of the COLMAP steps. ``matcher``: auto (exhaustive up to 150 images, else sequential + spatial,
    then exhaustive when the scene is still split into several models) | exhaustive | sequential;
    ``global_mapping``: GLOMAP instead of incremental mapping; ``refine_intrinsics``: let bundle adjustment
    refine the focal length; ``feature_scale``: SIFT upsampling, None for automatic;
    ``device``: auto | cpu | cuda; ``num_threads``: of feature extraction and matching (incremental mapping,
    fixed-pose triangulation and bundle adjustment run on one thread, ``colmap.MAPPER_THREADS``: reproducible);
    ``seed``: of COLMAP's RANSAC and mapper (two-view verification is seeded only when matching runs on several
    threads: ``colmap.verification_seed``). docs/sfm.md, "Reproducibility"."""

    matcher: str = field(default="auto", metadata=CONFIG)
    global_mapping: bool = field(default=False, metadata=CONFIG)
    refine_intrinsics: bool = field(default=False, metadata=CONFIG)
    feature_scale: int | None = field(default=None, metadata=CONFIG)
    max_num_features: int = field(default=8192, metadata=CONFIG)
    sequential_overlap: int | None = None  # default: 3 views' worth of latent images
    num_threads: int = 2
    device: str = field(default="auto", metadata=CONFIG)
    seed: int = field(default=0, metadata=CONFIG)
    enhance: bool = True  # contrast-stretch dark frames for SIFT
    # Incremental mapper on small (upsampled) frames: reprojection thresholds in original pixels. COLMAP's
    # defaults (4 px; 12 px for absolute pose) suit megapixel images; on 128×96 frames they admitted wrong
    # registrations that folded or bent the orbit (see docs/sfm.md).
    small_max_error_px: float = 1.0
    small_abs_pose_max_error_px: float = 2.0


@dataclass
class SfmConfig:
    """Stage options. ``mode``: auto (given when the scene's latent poses are ground truth and ``allow_given``,
    else colmap) | colmap | given | model (the poses of an existing COLMAP model at ``path``, checked against the
    scene's K within ``intrinsics_tolerance``: eigs.sfm.model); ``min_registered_fraction``: of the images given
    to COLMAP, below which the
    stage stops; ``interpolate_unregistered``: fill unregistered latents from registered latents of the same
    view; ``register_test_cameras``: register the ground-truth sharp images into the model (else the Sim(3)-mapped
    ground truth). ``keep_work``, ``verbose`` and ``plot`` are run control, not config options."""

    mode: str = "auto"
    allow_given: bool = True
    path: str | None = None  # model mode: the COLMAP sparse model directory
    intrinsics_tolerance: float = 0.01  # model mode: relative focal, principal point (fraction of the size)
    min_registered_fraction: float = 0.5
    interpolate_unregistered: bool = True
    register_test_cameras: bool = True
    keep_work: bool = False
    verbose: bool = False
    plot: bool = True
    colmap: ColmapOptions = field(default_factory=ColmapOptions)


_RUN_CONTROL = ("keep_work", "verbose", "plot", "colmap")
_COLMAP_CONFIG = tuple(f.name for f in fields(ColmapOptions) if f.metadata.get("config"))
# The keys of the `sfm:` config section (flat: the COLMAP options sit beside the stage's own).
SFM_CONFIG_KEYS = tuple(f.name for f in fields(SfmConfig) if f.name not in _RUN_CONTROL) + _COLMAP_CONFIG
CHOICES = {"mode": MODES, "matcher": MATCHERS, "device": DEVICES}  # the keys of `sfm:` that take one of a few values


def sfm_config(values: Mapping[str, Any], **run_control: Any) -> SfmConfig:
    """:class:`SfmConfig` from flat config keys (:data:`SFM_CONFIG_KEYS`, unset ones keep their defaults) and
    run-control fields (``keep_work``, ``verbose``, ``plot``, ``num_threads``)."""
    unknown = sorted(set(values) - set(SFM_CONFIG_KEYS))
    if unknown:
        raise EigsError("--config", f"unknown sfm option(s) {', '.join(unknown)}")
    col = {k: v for k, v in values.items() if k in _COLMAP_CONFIG}
    if "num_threads" in run_control:
        col["num_threads"] = run_control.pop("num_threads")
    top = {k: v for k, v in values.items() if k not in _COLMAP_CONFIG}
    return SfmConfig(**top, **run_control, colmap=ColmapOptions(**col))
