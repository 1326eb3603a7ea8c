"""The trainable Gaussian model: leaf tensors in the 3DGS parametrisation, their Adam optimiser, and conversion
from and to the on-disk :class:`~eigs.artifacts.gaussians.GaussianCloud`.

Parameters (N Gaussians, C colour channels, K = (d+1)² SH coefficients of the model's degree d):
``means`` (N, 3) world units; ``sh0`` (N, 1, C) DC coefficients; ``shN`` (N, K−1, C) the rest; ``log_scales``
(N, 3); ``quats`` (N, 4) w x y z (unnormalised); ``opacities`` (N,) logits.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from eigs.artifacts.gaussians import GaussianCloud
from eigs.render.gaussians import render_gaussians
from eigs.train.config import TrainConfig
from eigs.train.optim import Optimizer, adam
from eigs.util.schedule import exp_decay

PARAM_NAMES = ("means", "sh0", "shN", "log_scales", "quats", "opacities")


class GaussianModel:
    """Gaussian parameters as a dict of leaf tensors (``requires_grad``), one Adam param group each."""

    def __init__(self, params: dict[str, Tensor], sh_degree: int):
        self.params = params
        self.sh_degree = sh_degree

    # ------------------------------------------------------------------ construction and export
    @classmethod
    def from_cloud(cls, cloud: GaussianCloud, sh_degree: int, channels: int, device: torch.device) -> GaussianModel:
        """Model of degree ``sh_degree`` with ``channels`` colour channels (1: grey, the mean of the PLY's three
        DC channels; higher SH coefficients the cloud lacks start at zero, extra ones are dropped)."""
        sh = cloud.sh_coefficients(sh_degree, channels)  # (N, K, C)

        def leaf(a: np.ndarray) -> Tensor:
            return torch.tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device).requires_grad_(True)

        params = {
            "means": leaf(cloud.means),
            "sh0": leaf(sh[:, :1]),
            "shN": leaf(sh[:, 1:]),
            "log_scales": leaf(cloud.log_scales),
            "quats": leaf(cloud.quats),
            "opacities": leaf(cloud.opacity),
        }
        return cls(params, sh_degree)

    def to_cloud(self) -> GaussianCloud:
        """The model as a 3DGS PLY cloud (grey models store their channel three times; quaternions normalised)."""
        p = {name: t.detach().cpu().numpy().astype(np.float32) for name, t in self.params.items()}
        dc, shn = p["sh0"][:, 0, :], p["shN"]  # (N, C), (N, K, C)
        if dc.shape[1] == 1:
            dc, shn = np.repeat(dc, 3, axis=1), np.repeat(shn, 3, axis=2)
        q = p["quats"]
        q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-12)
        return GaussianCloud(
            means=p["means"],
            f_dc=dc,
            f_rest=np.ascontiguousarray(np.transpose(shn, (0, 2, 1))),
            opacity=p["opacities"],
            log_scales=p["log_scales"],
            quats=q.astype(np.float32),
        )

    # ------------------------------------------------------------------ rendering
    def __len__(self) -> int:
        return int(self.params["means"].shape[0])

    @property
    def sh(self) -> Tensor:
        """(N, K, C) all SH coefficients."""
        return torch.cat([self.params["sh0"], self.params["shN"]], dim=1)

    def render(
        self,
        c2w: Tensor,
        K: Tensor,
        width: int,
        height: int,
        background: Tensor | None,
        sh_degree: int | None = None,
        means: Tensor | None = None,
        quats: Tensor | None = None,
        log_scales: Tensor | None = None,
    ) -> tuple[Tensor, Tensor, dict]:
        """Render at ``c2w``; ``means``/``quats``/``log_scales`` replace the model's (moved Gaussians)."""
        p = self.params
        degree = self.sh_degree if sh_degree is None else sh_degree
        sh = p["sh0"] if degree == 0 else self.sh
        return render_gaussians(
            p["means"] if means is None else means,
            p["quats"] if quats is None else quats,
            p["log_scales"] if log_scales is None else log_scales,
            p["opacities"],
            sh,
            c2w,
            K,
            width,
            height,
            background=background,
            sh_degree=degree,
        )


def scene_extent(camera_centres: np.ndarray) -> float:
    """3DGS's spatial scale: 1.1 × the largest distance of a camera centre from their mean (≥ 1e-6)."""
    c = np.asarray(camera_centres, np.float64).reshape(-1, 3)
    c = c[np.all(np.isfinite(c), axis=1)]
    if c.shape[0] == 0:
        return 1.0
    return max(1.1 * float(np.linalg.norm(c - c.mean(axis=0), axis=1).max()), 1e-6)


def make_optimizer(model: GaussianModel, cfg: TrainConfig, extent: float) -> Optimizer:
    """Adam with one param group per parameter, named; eps 1e-15 as 3DGS. :func:`eigs.train.optim.adam` (fused)."""
    lrs = {
        "means": cfg.lr_means * extent,
        "sh0": cfg.lr_sh0,
        "shN": cfg.lr_shN,
        "log_scales": cfg.lr_scales,
        "quats": cfg.lr_quats,
        "opacities": cfg.lr_opacities,
    }
    groups = [{"params": [model.params[n]], "lr": lrs[n], "name": n} for n in PARAM_NAMES]
    return adam(groups, eps=1e-15)


def means_lr(cfg: TrainConfig, extent: float, step: int) -> float:
    """Exponential decay of the position learning rate from ``lr_means`` to ``lr_means_final`` (× ``extent``) over
    the schedule (``cfg.horizon`` steps: the run, or the longer schedule the run stops in)."""
    return exp_decay(cfg.lr_means * extent, cfg.lr_means_final * extent, step, cfg.horizon)
