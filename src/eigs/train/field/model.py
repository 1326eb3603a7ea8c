"""The trainable voxel-grid radiance field: the box from the initial points, the warp (a finer core around the
object), the grid (one leaf tensor of raw density and colour) and, for ``field: grid+vm``, VM colour factors
(:mod:`eigs.train.field.factors`), coarse-to-fine growth, the occupancy mask, total variation, export to the model
file.

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
from eigs.losses.grid_tv import grid_tv_grad_
from eigs.render.field import CHANNELS_LAST, FieldTensors, VMFactors
from eigs.train.field.factors import (
    grid_shape,
    grow_vm,
    make_vm,
    vm_arrays,
    vm_dims,
    vm_from_leaves,
    vm_tv_grad_,
)
from eigs.train.field.options import FieldOptions


def field_box(
    points: np.ndarray, opts: FieldOptions, cameras: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The box of the field: per axis the ``box_quantile`` and 1 − ``box_quantile`` quantiles of the points (N, 3),
    padded by ``box_margin`` × the extent each side, then grown to hold the camera centres (M, 3) ±
    ``box_camera_margin``."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    if p.shape[0] < 2:
        raise EigsError("field", "the initial point cloud needs at least two finite points to bound the field")
    lo = np.quantile(p, opts.box_quantile, axis=0)
    hi = np.quantile(p, 1.0 - opts.box_quantile, axis=0)
    ext = np.maximum(hi - lo, 1e-3 * max(float(np.max(hi - lo)), 1e-6))
    pad = opts.box_margin * ext
    lo, hi = lo - pad, hi + pad
    if cameras is not None:
        c = np.asarray(cameras, np.float64).reshape(-1, 3)
        c = c[np.all(np.isfinite(c), axis=1)]
        if c.shape[0]:
            lo = np.minimum(lo, c.min(axis=0) - opts.box_camera_margin)
            hi = np.maximum(hi, c.max(axis=0) + opts.box_camera_margin)
    return lo, hi


def core_box(
    points: np.ndarray, lo: np.ndarray, hi: np.ndarray, opts: FieldOptions
) -> tuple[np.ndarray, np.ndarray] | None:
    """The core of the field, where its voxels are ``core_ratio`` times finer than in the rest of the box: per axis
    the ``box_quantile`` .. 1 − ``box_quantile`` range of the points (N, 3) within ``core_radius`` of the origin
    (the cameras' centre in the canonical frame: the object and the floor around it), padded by ``box_margin`` ×
    its extent, inside the box. None (a uniform grid) when ``core_ratio`` is 1 or fewer than 8 points are near."""
    if opts.core_ratio <= 1.0:
        return None
    p = np.asarray(points, np.float64).reshape(-1, 3)
    p = p[np.all(np.isfinite(p), axis=1)]
    p = p[np.linalg.norm(p, axis=1) <= opts.core_radius]
    if p.shape[0] < 8:
        return None
    a, b = np.quantile(p, opts.box_quantile, axis=0), np.quantile(p, 1.0 - opts.box_quantile, axis=0)
    pad = opts.box_margin * (b - a)
    eps = 1e-3 * (np.asarray(hi) - np.asarray(lo))  # every segment of the warp keeps a positive length
    a = np.clip(a - pad, lo + eps, hi - 3 * eps)
    b = np.clip(b + pad, a + eps, hi - eps)
    return a, b


def make_warp(lo: np.ndarray, hi: np.ndarray, core: tuple[np.ndarray, np.ndarray] | None,
              ratio: float) -> tuple[np.ndarray | None, np.ndarray]:  # fmt: skip
    """The warp (2, 3, 4) of the box with a core [a, b] whose voxels are ``ratio`` times finer than the shells'
    (knots lo, a, b, hi ↦ the cumulative lengths in core-voxel units, normalised), and the box's extent (3,) in
    core-voxel units (what the grid's corner counts follow). Without a core: (None, hi − lo)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if core is None:
        return None, hi - lo
    xs = np.stack([lo, core[0], core[1], hi], axis=1)  # (3, 4)
    eff = np.diff(xs, axis=1) / np.array([ratio, 1.0, ratio])  # (3, 3) segment lengths in core units
    extent = eff.sum(axis=1)
    us = np.concatenate([np.zeros((3, 1)), np.cumsum(eff, axis=1)], axis=1) / extent[:, None]
    us[:, -1] = 1.0
    return np.stack([xs, us]), extent


def warp_np(warp: np.ndarray | None, lo: np.ndarray, hi: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Normalised grid coordinates (N, 3) in [0, 1] of world points (N, 3) (NumPy; the renderer's map)."""
    p = np.asarray(points, np.float64)
    if warp is None:
        return np.clip((p - lo) / (hi - lo), 0.0, 1.0)
    return np.stack([np.interp(p[:, a], warp[0, a], warp[1, a]) for a in range(3)], axis=1)


def grid_voxels(extent: np.ndarray, voxels: int) -> int:
    """Corner count of the grid :func:`grid_shape` gives for ``voxels``."""
    return int(np.prod(grid_shape(extent, voxels)))


def voxel_schedule(opts: FieldOptions, steps: int, vm: bool = False) -> list[tuple[int, int]]:
    """(step, voxels) of every growth: the start count at step 0, then geometric steps to the final count
    (``voxels_start`` .. ``voxels_final``; with ``vm`` those of the VM factors, ``vm_voxels_start`` ..
    ``vm_voxels_final``)."""
    k = len(opts.grow_at)
    start, final = (opts.vm_voxels_start, opts.vm_voxels_final) if vm else (opts.voxels_start, opts.voxels_final)
    out = [(0, start)]
    for i, frac in enumerate(opts.grow_at, start=1):
        v = start * (final / start) ** (i / k)
        out.append((max(int(frac * steps), 1), int(round(v))))
    return out


class FieldModel:
    """The grid as a leaf tensor plus the box and the occupancy mask (not trained)."""

    def __init__(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        channels: int,
        opts: FieldOptions,
        device: torch.device,
        points: np.ndarray | None = None,
        colours: np.ndarray | None = None,
    ):
        """``points`` (N, 3) and ``colours`` (N, channels) in [0, 1]: the SfM points that seed the grid when
        ``opts.init_from_points``."""
        self.opts = opts
        self.device = device
        self.lo_np, self.hi_np = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        self.lo = torch.tensor(self.lo_np, dtype=torch.float32, device=device)
        self.hi = torch.tensor(self.hi_np, dtype=torch.float32, device=device)
        core = core_box(points, self.lo_np, self.hi_np, opts) if points is not None else None
        self.warp, self.extent = make_warp(self.lo_np, self.hi_np, core, opts.core_ratio)
        shape = grid_shape(self.extent, opts.voxels_start)
        # (1, 1 + C, Z, Y, X) stored channels last (CHANNELS_LAST): the trilinear kernel reads it and writes its
        # gradient in place, where a contiguous grid costs a copy each way every render (~30 ms a step at 96³)
        grid = torch.zeros((1, 1 + channels, *shape), device=device)
        self.grid = grid.contiguous(memory_format=CHANNELS_LAST).requires_grad_(True)
        self.occupancy = torch.ones(shape, dtype=torch.bool, device=device)
        self.max_weight = torch.zeros(shape, device=device)  # per voxel, since the last occupancy update
        sigma0 = -math.log1p(-opts.alpha_init) / self.sample_interval()
        self.density_scale = opts.density_scale
        self.density_shift = math.log(math.expm1(sigma0 / self.density_scale))  # scale · softplus(0 + shift) = sigma0
        if opts.init_from_points and points is not None and colours is not None and len(points):
            self.seed_from_points(np.asarray(points, np.float64), np.asarray(colours, np.float64))
        # "grid+vm": VM colour factors whose raw colour adds to the grid's (detail finer than its voxels)
        self.vm: VMFactors | None = None
        if opts.field == "grid+vm":
            self.vm = make_vm(vm_dims(self.extent, opts.vm_voxels_start), 0, opts.vm_colour_channels, channels,
                              opts.vm_init_scale, device)  # fmt: skip

    @torch.no_grad()
    def seed_from_points(self, points: np.ndarray, colours: np.ndarray) -> None:
        """Voxel corners within one voxel of a point (3³ neighbourhood of its nearest corner) get the mean colour
        of those points and the density of α = 0.5 over one voxel edge."""
        z, y, x = self.grid.shape[2:]
        dims = np.array([x, y, z], np.float64)
        inside = np.all((points >= self.lo_np) & (points <= self.hi_np), axis=1)
        idx = np.round(warp_np(self.warp, self.lo_np, self.hi_np, points) * (dims - 1)).astype(np.int64)
        idx, colours = idx[inside], colours[inside]
        if not len(idx):
            return
        flat = torch.from_numpy((idx[:, 2] * y + idx[:, 1]) * x + idx[:, 0])
        count = torch.zeros(z * y * x, dtype=torch.float64)
        count.index_add_(0, flat, torch.ones(len(flat), dtype=torch.float64))
        csum = torch.zeros((z * y * x, colours.shape[1]), dtype=torch.float64)
        csum.index_add_(0, flat, torch.from_numpy(colours))
        vol = torch.cat([count[:, None], csum], dim=1).T.reshape(1, 1 + colours.shape[1], z, y, x)
        vol = F.avg_pool3d(vol, kernel_size=3, stride=1, padding=1, count_include_pad=False)[0]
        near = vol[0] > 0
        mean = (vol[1:] / vol[:1].clamp_min(1e-12)).clamp(0.02, 0.98)
        sigma = math.log(2.0) / self.voxel_size()
        raw_density = math.log(math.expm1(sigma / self.density_scale)) - self.density_shift
        g = self.grid.detach().clone()
        g[0, 0][near] = raw_density
        logit = torch.log(mean / (1 - mean)).to(g.dtype)
        g[0, 1:][:, near] = logit[:, near]
        self.grid = g.requires_grad_(True)

    @property
    def channels(self) -> int:
        return int(self.grid.shape[1]) - 1

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.grid.shape[2:]))

    def voxel_size(self) -> float:
        """Edge of the finest voxels (the core's), world units."""
        z, y, x = self.grid.shape[2:]
        return float(np.min(self.extent / (np.array([x, y, z], np.float64) - 1)))

    def n_samples(self) -> int:
        """Samples per ray on the current grid: ``n_samples`` × its resolution relative to the final grid (≥ 16)."""
        o = self.opts
        rel = (self.n_voxels / grid_voxels(self.extent, o.voxels_final)) ** (1.0 / 3.0)
        return max(min(int(round(o.n_samples * rel)), o.n_samples), min(16, o.n_samples))

    def tensors(self) -> FieldTensors:
        o = self.opts
        return FieldTensors(
            self.grid, self.lo, self.hi, self.occupancy, self.density_shift, self.n_samples(), o.near, self.warp,
            self.vm, self.density_scale,
        )

    # ------------------------------------------------------------------ growth and occupancy
    @torch.no_grad()
    def grow(self, voxels: int, vm_voxels: int | None = None) -> None:
        """Resample the grid (trilinear, corners aligned) to about ``voxels`` voxels; occupancy follows (nearest);
        the VM colour factors, if any, to the corner counts of ``vm_voxels``."""
        if self.vm is not None and vm_voxels is not None:
            self.vm = grow_vm(self.vm, vm_dims(self.extent, vm_voxels))
        shape = grid_shape(self.extent, voxels)
        # interpolated in the contiguous layout: PyTorch's channels-last upsampling rounds differently
        new = F.interpolate(self.grid.detach().contiguous(), size=shape, mode="trilinear", align_corners=True)
        occ = F.interpolate(self.occupancy[None, None].float(), size=shape, mode="nearest")[0, 0] > 0
        self.max_weight = F.interpolate(self.max_weight[None, None], size=shape, mode="nearest")[0, 0]
        self.grid = new.contiguous(memory_format=CHANNELS_LAST).requires_grad_(True)
        self.occupancy = occ

    def sample_interval(self) -> float:
        """Length of one sample interval of the longest ray through the box on the current grid (its diagonal /
        :meth:`n_samples`); every other interval, and every later one (more samples on finer grids), is shorter."""
        return float(np.linalg.norm(self.hi_np - self.lo_np)) / self.n_samples()

    @torch.no_grad()
    def record_weights(self, voxels: Tensor, weights: Tensor) -> None:
        """Keep the largest compositing weight of each voxel's samples (flat voxel indices, weights (N,))."""
        self.max_weight.view(-1).scatter_reduce_(0, voxels, weights.to(self.max_weight.dtype), reduce="amax")

    @torch.no_grad()
    def update_occupancy(self) -> float:
        """Mark occupied the voxels a sample of which had a compositing weight of ``occupancy_weight`` or more since
        the last update, dilated by one voxel (max-pool 3³); start a new record. Returns the occupied fraction."""
        occ = self.max_weight >= self.opts.occupancy_weight
        occ = F.max_pool3d(occ[None, None].float(), kernel_size=3, stride=1, padding=1)[0, 0] > 0
        self.occupancy = occ
        self.max_weight = torch.zeros_like(self.max_weight)
        return float(occ.float().mean())

    # ------------------------------------------------------------------ regularisers, export
    def total_variation(self) -> tuple[Tensor, Tensor]:
        """Mean squared differences of neighbouring raw values: (density, colour)."""
        g = self.grid[0]

        def tv(x: Tensor) -> Tensor:
            return sum((x.diff(dim=d) ** 2).mean() for d in (1, 2, 3)) / 3.0  # type: ignore[return-value]

        return tv(g[:1]), tv(g[1:])

    @torch.no_grad()
    def add_total_variation_grad(self, w_density: float, w_colour: float) -> float:
        """Add the gradient of ``w_density`` · TV(density) + ``w_colour`` · TV(colour) (:meth:`total_variation`'s
        terms) to ``grid.grad`` in place (created when missing), without autograd
        (:func:`eigs.losses.grid_tv.grid_tv_grad_`). Returns the weighted value."""
        if self.grid.grad is None:
            self.grid.grad = torch.zeros_like(self.grid)
        # (Z, Y, X, 1 + C) views: contiguous in the grid's own layout (channels last), where the kernel runs
        g, grad = self.grid[0].permute(1, 2, 3, 0), self.grid.grad[0].permute(1, 2, 3, 0)
        total = grid_tv_grad_(g, grad, [(0, 1, w_density / 3.0), (1, 1 + self.channels, w_colour / 3.0)])
        if self.vm is not None:
            total += vm_tv_grad_(self.vm, 0.0, self.opts.vm_tv_colour)
        return total

    def leaves(self) -> list[Tensor]:
        return [self.grid, *(self.vm.leaves() if self.vm is not None else [])]

    def param_groups(self) -> list[dict]:
        """Adam groups: the grid at ``lr_grid``; VM colour factors at ``lr_factors``, their basis at ``lr_basis``
        (``base_lr``: what the decay scales)."""
        o = self.opts
        groups = [{"params": [self.grid], "lr": o.lr_grid, "base_lr": o.lr_grid}]
        if self.vm is not None:
            groups += [{"params": self.vm.leaves()[:-1], "lr": o.lr_factors, "base_lr": o.lr_factors},
                       {"params": [self.vm.basis], "lr": o.lr_basis, "base_lr": o.lr_basis}]  # fmt: skip
        return groups

    def shape(self) -> list[int]:
        return list(self.grid.shape[2:])

    def to_arrays(self) -> FieldArrays:
        o = self.opts
        return FieldArrays(
            grid=self.grid.detach()[0].cpu().numpy().astype(np.float32),
            lo=self.lo_np.copy(),
            hi=self.hi_np.copy(),
            occupancy=self.occupancy.cpu().numpy().astype(bool),
            density_shift=float(self.density_shift),
            density_scale=float(self.density_scale),
            n_samples=self.n_samples(),
            near=float(o.near),
            warp=None if self.warp is None else self.warp.copy(),
            vm=None if self.vm is None else vm_arrays(self.vm),
        )

    def state_dict(self) -> dict:
        vm = None if self.vm is None else [t.detach().cpu() for t in self.vm.leaves()]
        return {"grid": self.grid.detach().cpu(), "occupancy": self.occupancy.cpu(),
                "max_weight": self.max_weight.cpu(), "vm": vm}  # fmt: skip

    def load_state_dict(self, state: dict) -> None:
        if state.get("vm") is not None:
            self.vm = vm_from_leaves([t.to(self.device).requires_grad_(True) for t in state["vm"]], density=False)
        self.grid = state["grid"].to(self.device).contiguous(memory_format=CHANNELS_LAST).requires_grad_(True)
        self.occupancy = state["occupancy"].to(self.device)
        self.max_weight = state["max_weight"].to(self.device)


def lr_factor(opts: FieldOptions, step: int, steps: int) -> float:
    """The decay factor of every field learning rate at ``step``: 1 at the start, ``lr_decay`` at the end."""
    t = min(max(step / max(steps, 1), 0.0), 1.0)
    return math.exp(math.log(max(opts.lr_decay, 1e-12)) * t)
