"""Densification and pruning (3DGS's adaptive density control, gsplat ``DefaultStrategy`` semantics).

Hooks: :meth:`DensifyStrategy.after_backward` accumulates the screen-space gradient of each Gaussian after every
step; :meth:`DensifyStrategy.after_step` grows (clone small / split large Gaussians whose mean gradient exceeds
``grow_grad2d``), prunes (transparent, and after the first opacity reset oversized) and periodically resets
opacities. Every change remaps the Adam state row by row: kept rows keep their moments, clones copy them, split
children start at zero.

Units: the rasterizer's ``means2d`` gradient is in pixels; 3DGS's threshold is in NDC, so the gradient is scaled by
W/2 in x and H/2 in y. A step that renders several images (EiGS: N+1 moved copies) counts once for a Gaussian
visible in any of them, so a step has the same weight whatever the number of renders; its statistic per Gaussian is
``grow_grad2d_renders``: the norm of the renders' summed ``means2d`` gradients (``vector_sum``, 3DGS's statistic) or
the sum of each render's norm (``norm_sum``: the renders' pulls do not cancel where they disagree; equal to
``vector_sum`` when they agree, and for one render).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import torch
from torch import Tensor

from eigs.train.config import TrainConfig
from eigs.train.gaussian.model import PARAM_NAMES, GaussianModel
from eigs.train.optim import Optimizer

log = logging.getLogger(__name__)


def quat_to_rotmat(q: Tensor) -> Tensor:
    """(N, 4) w x y z (any norm) → (N, 3, 3) rotation matrices."""
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(-1, 3, 3)  # fmt: skip


def remap_gaussians(
    model: GaussianModel,
    optimizer: Optimizer,
    keep: Tensor,
    new: dict[str, Tensor] | None = None,
    new_state_from: Tensor | None = None,
) -> None:
    """Replace every Gaussian parameter by ``cat(p[keep], new[name])`` and its Adam moments by
    ``cat(m[keep], m[new_state_from] or zeros)``. ``keep``: (M,) int64 rows; ``new``: name → (A, …) rows."""
    n_new = 0 if new is None else int(next(iter(new.values())).shape[0])
    for group in optimizer.param_groups:
        name = group.get("name")
        if name not in PARAM_NAMES:
            continue
        old = group["params"][0]
        data = old.detach()[keep]
        if n_new:
            data = torch.cat([data, new[name].to(data.dtype)])  # type: ignore[index]
        param = data.contiguous().requires_grad_(True)
        state = optimizer.state.pop(old, None)
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                if key in state:
                    m = state[key][keep]
                    if n_new:
                        extra = (
                            state[key][new_state_from]
                            if new_state_from is not None
                            else state[key].new_zeros((n_new, *state[key].shape[1:]))
                        )
                        m = torch.cat([m, extra])
                    state[key] = m.contiguous()
            optimizer.state[param] = state
        group["params"][0] = param
        model.params[name] = param


@dataclass
class RefineReport:
    step: int
    cloned: int = 0
    split: int = 0
    pruned: int = 0
    reset: bool = False


class DensifyStrategy:
    """Adaptive density control. ``extent``: the scene's spatial scale; ``width``, ``height``: image size (px)."""

    def __init__(self, cfg: TrainConfig, extent: float, width: int, height: int, seed: int = 0):
        self.cfg = cfg
        self.extent = extent
        self.half = (width / 2.0, height / 2.0)
        self.grad2d: Tensor | None = None  # (N,) summed NDC gradient norms
        self.count: Tensor | None = None  # (N,) steps in which each Gaussian was visible
        self.generator = torch.Generator().manual_seed(seed)

    # ------------------------------------------------------------------ state for checkpoints
    def state_dict(self) -> dict:
        return {"grad2d": self.grad2d, "count": self.count, "generator": self.generator.get_state()}

    def load_state_dict(self, state: dict) -> None:
        self.grad2d, self.count = state["grad2d"], state["count"]
        self.generator.set_state(state["generator"])

    # ------------------------------------------------------------------ hooks
    def active(self, step: int) -> bool:
        """Whether gradient statistics are collected at ``step`` (0-based, before the optimiser step)."""
        return self.cfg.densify and step < self.cfg.refine_stop

    def after_backward(self, model: GaussianModel, infos: list[dict]) -> None:
        """Accumulate the screen-space gradients of one step's renders (each ``info`` from the rasterizer with
        ``means2d`` gradients retained; renders of other cameras or moved copies of the same Gaussians)."""
        n = len(model)
        if self.grad2d is None or self.grad2d.shape[0] != n:
            self.grad2d = torch.zeros(n)
            self.count = torch.zeros(n)
        per_render = self.cfg.grow_grad2d_renders == "norm_sum"
        half = torch.tensor(self.half, dtype=torch.float32)
        g = torch.zeros(n, 2)  # (N, 2) vector_sum: the renders' summed pixel gradients
        norm = torch.zeros(n)  # (N,) norm_sum: the renders' summed NDC norms
        visible = torch.zeros(n, dtype=torch.bool)
        for info in infos:
            m2d = info["means2d"]
            if m2d.grad is None:
                continue
            g_render = m2d.grad.detach().reshape(n, 2).to(torch.float32).cpu()  # (N, 2) px
            if per_render:
                norm += (g_render * half).norm(dim=-1)
            else:
                g += g_render
            visible |= (info["radii"].reshape(n, -1) > 0).any(dim=-1).cpu()
        if not per_render:
            g[:, 0] *= self.half[0]
            g[:, 1] *= self.half[1]
            norm = g.norm(dim=-1)
        norm = torch.where(torch.isfinite(norm), norm, torch.zeros_like(norm))
        self.grad2d += torch.where(visible, norm, torch.zeros_like(norm))
        self.count += visible.to(torch.float32)  # type: ignore[operator]

    @torch.no_grad()
    def after_step(self, step: int, model: GaussianModel, optimizer: Optimizer) -> RefineReport | None:
        """Refine after optimiser step ``step`` (1-based count of steps done). Returns what changed, or None."""
        cfg = self.cfg
        if not cfg.densify:
            return None
        report = None
        if step >= cfg.refine_start and step < cfg.refine_stop and step % cfg.refine_every == 0:
            report = self._refine(step, model, optimizer)
        if cfg.reset_every and step % cfg.reset_every == 0 and step < cfg.refine_stop:
            self._reset_opacities(model, optimizer)
            report = report or RefineReport(step)
            report.reset = True
        return report

    # ------------------------------------------------------------------ operations
    def _refine(self, step: int, model: GaussianModel, optimizer: Optimizer) -> RefineReport:
        cfg = self.cfg
        p = model.params
        n = len(model)
        device = p["means"].device
        report = RefineReport(step)
        if self.grad2d is not None and self.grad2d.shape[0] == n:
            grads = self.grad2d / self.count.clamp_min(1.0)  # type: ignore[union-attr]
            high = grads > cfg.grow_grad2d
            small = torch.exp(p["log_scales"]).max(dim=-1).values.cpu() <= cfg.grow_scale3d * self.extent
            cand = torch.nonzero(high).squeeze(1)
            budget = max(cfg.max_gaussians - n, 0)
            # a split adds one net Gaussian (two children replace the parent), a clone one
            if cand.numel() > budget:
                order = torch.argsort(grads[cand], descending=True, stable=True)
                cand = cand[order[:budget]]
            is_small = small[cand]
            clone_idx, split_idx = cand[is_small].to(device), cand[~is_small].to(device)
            report.cloned, report.split = int(clone_idx.numel()), int(split_idx.numel())
            if clone_idx.numel():
                remap_gaussians(
                    model,
                    optimizer,
                    torch.arange(n, device=device),
                    {k: v.detach()[clone_idx] for k, v in p.items()},
                    new_state_from=clone_idx,
                )
            if split_idx.numel():
                self._split(model, optimizer, split_idx)
        # prune: transparent, and after the first opacity reset, oversized
        opac = torch.sigmoid(p["opacities"].detach())
        prune = opac < cfg.prune_opacity
        if cfg.reset_every and step > cfg.reset_every:
            prune |= torch.exp(p["log_scales"].detach()).max(dim=-1).values > cfg.prune_scale3d * self.extent
        if bool(prune.all()):  # never prune the last Gaussian away: keep the most opaque one
            prune[torch.argmax(opac)] = False
        if bool(prune.any()):
            report.pruned = int(prune.sum())
            remap_gaussians(model, optimizer, torch.nonzero(~prune).squeeze(1))
        self.grad2d = torch.zeros(len(model))
        self.count = torch.zeros(len(model))
        return report

    def _split(self, model: GaussianModel, optimizer: Optimizer, idx: Tensor) -> None:
        """Replace each Gaussian of ``idx`` by two children sampled from it, scales divided by 1.6 (3DGS)."""
        p = {k: v.detach() for k, v in model.params.items()}
        n = p["means"].shape[0]
        scales = torch.exp(p["log_scales"][idx])  # (S, 3)
        rot = quat_to_rotmat(p["quats"][idx])  # (S, 3, 3)
        noise = torch.randn((2, idx.numel(), 3), generator=self.generator).to(scales)
        offsets = torch.einsum("sij,bsj->bsi", rot, scales[None] * noise)  # (2, S, 3)
        new = {k: v[idx].repeat(2, *([1] * (v.dim() - 1))) for k, v in p.items()}
        new["means"] = (p["means"][idx][None] + offsets).reshape(-1, 3)
        new["log_scales"] = (p["log_scales"][idx] - math.log(1.6)).repeat(2, 1)
        keep = torch.ones(n, dtype=torch.bool, device=idx.device)
        keep[idx] = False
        remap_gaussians(model, optimizer, torch.nonzero(keep).squeeze(1), new, new_state_from=None)

    def _reset_opacities(self, model: GaussianModel, optimizer: Optimizer) -> None:
        """Clamp opacities to 2 × the pruning threshold and zero their Adam moments (3DGS's reset)."""
        ceiling = 2.0 * self.cfg.prune_opacity
        logit = math.log(ceiling / (1.0 - ceiling))
        p = model.params["opacities"]
        p.data.clamp_(max=logit)
        state = optimizer.state.get(p)
        if state:
            for key in ("exp_avg", "exp_avg_sq"):
                if key in state:
                    state[key].zero_()
