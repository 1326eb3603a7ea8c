"""The trainable voxel-grid radiance field: the box from the initial points, the grid (one leaf tensor of raw
density and colour), coarse-to-fine growth, the occupancy mask, total variation, export to the model file.

Shapes: ``grid`` (1, 1 + C, Z, Y, X) (x the last axis); the box [lo, hi] in world units of the canonical SfM frame.
"""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from eigs.artifacts.field import FieldArrays
from eigs.errors import EigsError
from eigs.render.field import FieldTensors
from eigs.train.field_config import FieldOptions


def field_box(points: np.ndarray, opts: FieldOptions) -> tuple[np.ndarray, np.ndarray]:
    """The box of the field: per axis the ``box_quantile`` and 1 − ``box_quantile`` quantiles of the points (N, 3),
    padded by ``box_margin`` × the extent each side."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < 2:
        raise EigsError("field", "the initial point cloud needs at least two finite points to bound the field")
    lo = np.quantile(p, opts.box_quantile, axis=0)
    hi = np.quantile(p, 1.0 - opts.box_quantile, axis=0)
    ext = np.maximum(hi - lo, 1e-3 * max(float(np.max(hi - lo)), 1e-6))
    pad = opts.box_margin * ext
    return lo - pad, hi + pad


def grid_shape(lo: np.ndarray, hi: np.ndarray, voxels: int) -> tuple[int, int, int]:
    """(Z, Y, X) corner counts for about ``voxels`` cubic voxels over the box (each ≥ 2)."""
    ext = np.asarray(hi, np.float64) - np.asarray(lo, np.float64)
    size = (float(np.prod(ext)) / max(voxels, 1)) ** (1.0 / 3.0)
    n = np.maximum(np.round(ext / size).astype(int) + 1, 2)
    return int(n[2]), int(n[1]), int(n[0])


def voxel_schedule(opts: FieldOptions, steps: int) -> list[tuple[int, int]]:
    """(step, voxels) of every growth: voxels_start at step 0, then geometric steps to voxels_final."""
    k = len(opts.grow_at)
    out = [(0, opts.voxels_start)]
    for i, frac in enumerate(opts.grow_at, start=1):
        v = opts.voxels_start * (opts.voxels_final / opts.voxels_start) ** (i / k)
        out.append((max(int(frac * steps), 1), int(round(v))))
    return out


class FieldModel:
    """The grid as a leaf tensor plus the box and the occupancy mask (not trained)."""

    def __init__(self, lo: np.ndarray, hi: np.ndarray, channels: int, opts: FieldOptions, device: torch.device):
        self.opts = opts
        self.device = device
        self.lo_np, self.hi_np = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.lo = torch.tensor(self.lo_np, dtype=torch.float32, device=device)
        self.hi = torch.tensor(self.hi_np, dtype=torch.float32, device=device)
        shape = grid_shape(self.lo_np, self.hi_np, opts.voxels_start)
        self.grid = torch.zeros((1, 1 + channels, *shape), device=device).requires_grad_(True)
        self.occupancy = torch.ones(shape, dtype=torch.bool, device=device)
        sigma0 = -math.log1p(-opts.alpha_init) / self.sample_interval()
        self.density_shift = math.log(math.expm1(sigma0))  # softplus(0 + shift) = sigma0

    @property
    def channels(self) -> int:
        return int(self.grid.shape[1]) - 1

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.grid.shape[2:]))

    def tensors(self) -> FieldTensors:
        o = self.opts
        return FieldTensors(self.grid, self.lo, self.hi, self.occupancy, self.density_shift, o.n_samples, o.near)

    # ------------------------------------------------------------------ growth and occupancy
    @torch.no_grad()
    def grow(self, voxels: int) -> None:
        """Resample the grid (trilinear, corners aligned) to about ``voxels`` voxels; occupancy follows (nearest)."""
        shape = grid_shape(self.lo_np, self.hi_np, voxels)
        new = F.interpolate(self.grid.detach(), size=shape, mode="trilinear", align_corners=True)
        occ = F.interpolate(self.occupancy[None, None].float(), size=shape, mode="nearest")[0, 0] > 0
        self.grid = new.contiguous().requires_grad_(True)
        self.occupancy = occ

    def sample_interval(self) -> float:
        """Length of one sample interval of the longest ray through the box (its diagonal / n_samples)."""
        return float(np.linalg.norm(self.hi_np - self.lo_np)) / self.opts.n_samples

    @torch.no_grad()
    def update_occupancy(self) -> float:
        """Mark occupied the voxels whose α over one sample interval reaches ``occupancy_alpha``, dilated by one
        voxel (max-pool 3³). Returns the occupied fraction."""
        sig = F.softplus(self.grid[0, 0] + self.density_shift)
        alpha = -torch.expm1(-sig * self.sample_interval())
        occ = alpha >= self.opts.occupancy_alpha
        occ = F.max_pool3d(occ[None, None].float(), kernel_size=3, stride=1, padding=1)[0, 0] > 0
        self.occupancy = occ
        return float(occ.float().mean())

    # ------------------------------------------------------------------ regularisers, export
    def total_variation(self) -> tuple[Tensor, Tensor]:
        """Mean squared differences of neighbouring raw values: (density, colour)."""
        g = self.grid[0]

        def tv(x: Tensor) -> Tensor:
            return sum((x.diff(dim=d) ** 2).mean() for d in (1, 2, 3)) / 3.0  # type: ignore[return-value]

        return tv(g[:1]), tv(g[1:])

    def to_arrays(self) -> FieldArrays:
        o = self.opts
        return FieldArrays(
            grid=self.grid.detach()[0].cpu().numpy().astype(np.float32),
            lo=self.lo_np.copy(),
            hi=self.hi_np.copy(),
            occupancy=self.occupancy.cpu().numpy().astype(bool),
            density_shift=float(self.density_shift),
            n_samples=int(o.n_samples),
            near=float(o.near),
        )

    def state_dict(self) -> dict:
        return {"grid": self.grid.detach().cpu(), "occupancy": self.occupancy.cpu()}

    def load_state_dict(self, state: dict) -> None:
        self.grid = state["grid"].to(self.device).requires_grad_(True)
        self.occupancy = state["occupancy"].to(self.device)


def lr_at(opts: FieldOptions, step: int, steps: int) -> float:
    """Exponential decay of the grid learning rate from ``lr_grid`` to ``lr_grid · lr_decay`` over the run."""
    t = min(max(step / max(steps, 1), 0.0), 1.0)
    return opts.lr_grid * math.exp(math.log(max(opts.lr_decay, 1e-12)) * t)
