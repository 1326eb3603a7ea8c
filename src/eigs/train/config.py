"""Training options: :class:`TrainConfig` is the one source of every default (the CLI, the workflow's ``runs:``
section and ``config.json`` of a run all go through it).

Units: learning rates per Adam step; ``lr_means`` is multiplied by the scene extent (3DGS's spatial learning-rate
scale; in the canonical frame the RMS camera radius is 1, so the extent is ~1.1); steps are optimiser steps (one
training sample each); thresholds of densification in the units 3DGS uses (``grow_grad2d`` in NDC, ``grow_scale3d``
and ``prune_scale3d`` as fractions of the scene extent).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any, ClassVar

from eigs.util.options import Options, choice, parse_config_json

GROW_GRAD2D_RENDERS = ("vector_sum", "norm_sum")


@dataclass(frozen=True)
class TrainConfig(Options):
    """Every training hyperparameter, with its default. A method's own options are ``method_options``, as the run
    gives them (the method's options dataclass parses them once: :func:`eigs.train.resolve.resolve_run`)."""

    kind: ClassVar[str] = "training option"

    method: str = "3dgs"
    steps: int = 3000
    # length of the schedules (position lr decay, densification window); 0 = `steps`. A run with steps < this stops
    # part-way through a longer schedule: it equals the first `steps` steps of the run with steps = schedule_steps
    schedule_steps: int = 0
    seed: int = 0
    sh_degree: int = 0
    sh_degree_interval: int = 1000  # raise the active SH degree by one every this many steps (3DGS)
    # Adam learning rates (3DGS defaults except lr_means: the paper's 1.6e-3 for short CPU runs, see docs/training.md)
    lr_means: float = 1.6e-3
    lr_means_final: float = 1.6e-5
    lr_sh0: float = 2.5e-3
    lr_shN: float = 2.5e-3 / 20
    lr_opacities: float = 5e-2
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lambda_dssim: float = 0.2
    # the data range L of the training loss's SSIM constants, C1 = (0.01 L)², C2 = (0.03 L)², images in [0, 1]: 1 as
    # 3DGS; below 1 for dark frames, whose local contrast the constants would otherwise swamp (docs/training.md)
    ssim_range: float = 1.0
    # camera refinement, Gaussian methods only (eigs.train.gaussian.camera_refine: a learned SE(3) correction per
    # training view; its schedule and regulariser are BAD-Gaussians', docs/training.md "Camera refinement")
    camera_refine: bool = False
    lr_camera: float = 1e-3
    lr_camera_final: float = 1e-6
    camera_reg: float = 1e-6  # Adam weight decay on the twists
    # densification (3DGS / gsplat DefaultStrategy semantics; the paper's prune 1e-2, densify 5e-4)
    densify: bool = True
    refine_start: int = 300
    refine_stop_frac: float = 0.6  # stop growing after this fraction of the steps
    refine_every: int = 100
    reset_every: int = 0  # opacity reset every this many steps (0 = never: measured better for short runs)
    grow_grad2d: float = 5e-4
    # how a step that renders several images (EiGS's B + 1 latent renders, a trajectory's sub-frames) adds up their
    # screen-space gradients per Gaussian: "vector_sum", the norm of the summed vectors (3DGS's statistic: the renders'
    # pulls cancel where they disagree), or "norm_sum", the sum of each render's norm (no cancellation between
    # renders). The same for one render. docs/training.md "Densification"
    grow_grad2d_renders: str = choice("vector_sum", GROW_GRAD2D_RENDERS)
    grow_scale3d: float = 0.01
    prune_opacity: float = 1e-2
    prune_scale3d: float = 0.1
    max_gaussians: int = 200_000
    # bookkeeping
    log_every: int = 50
    eval_every: int = 250  # held-out PSNR every this many steps (0 = never)
    checkpoint_every: int = 500
    max_bad_steps: int = 20  # consecutive non-finite steps before the run stops
    method_options: dict[str, Any] = field(default_factory=dict)

    def problems(self) -> list[str]:
        checks = [
            (self.steps >= 1, "steps must be >= 1"),
            (self.schedule_steps >= 0, "schedule_steps must be >= 0 (0 = steps)"),
            (0 <= self.sh_degree <= 3, "sh_degree must lie in 0..3"),
            (self.sh_degree_interval >= 1, "sh_degree_interval must be >= 1"),
            (0 <= self.lambda_dssim <= 1, "lambda_dssim must lie in [0, 1]"),
            (0 < self.ssim_range <= 1, "ssim_range must lie in (0, 1]"),
            (self.refine_every >= 1, "refine_every must be >= 1"),
            (0 <= self.refine_stop_frac <= 1, "refine_stop_frac must lie in [0, 1]"),
            (self.log_every >= 1 and self.checkpoint_every >= 1, "log_every and checkpoint_every must be >= 1"),
            (self.eval_every >= 0 and self.reset_every >= 0, "eval_every and reset_every must be >= 0"),
            (self.max_bad_steps >= 1, "max_bad_steps must be >= 1"),
            (self.max_gaussians >= 1, "max_gaussians must be >= 1"),
        ]
        for name in ("lr_means", "lr_means_final", "lr_sh0", "lr_shN", "lr_opacities", "lr_scales", "lr_quats",
                     "lr_camera", "lr_camera_final", "camera_reg"):  # fmt: skip
            checks.append((getattr(self, name) >= 0, f"{name} must be >= 0"))
        return [msg for ok, msg in checks if not ok]

    @property
    def horizon(self) -> int:
        """Steps the schedules span: ``schedule_steps``, or ``steps`` when it is 0."""
        return self.schedule_steps or self.steps

    @property
    def refine_stop(self) -> int:
        return int(self.refine_stop_frac * self.horizon)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, text: str, where: str = "train config") -> TrainConfig:
        """From a JSON object (blank: ``{}``): :func:`eigs.util.options.parse_config_json`, then :meth:`from_dict`."""
        return cls.from_dict(parse_config_json(text, where), where)
