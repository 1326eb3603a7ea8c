"""Helpers of the radiance fields' parameters: the dense grid's shape for a voxel count, the in-place gradient of
total variation, and TensoRF's vector-matrix factors (:class:`eigs.render.field.VMFactors`): new, grown, their total
variation, as stored, from a checkpoint."""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from eigs.artifacts.field import VMArrays
from eigs.render.field import LINE_AXES, PLANE_AXES, VMFactors


def grid_shape(extent: np.ndarray, voxels: int) -> tuple[int, int, int]:
    """(Z, Y, X) corner counts for about ``voxels`` cubic voxels over a box of ``extent`` (3,) (each ≥ 2)."""
    ext = np.asarray(extent, np.float64)
    size = (float(np.prod(ext)) / max(voxels, 1)) ** (1.0 / 3.0)
    n = np.maximum(np.round(ext / size).astype(int) + 1, 2)
    return int(n[2]), int(n[1]), int(n[0])


@torch.no_grad()
def tv_grad_(x: Tensor, gx: Tensor, w: float, dims: tuple[int, ...] | list[int]) -> float:
    """Add to ``gx`` in place the gradient of w · Σ_{d ∈ dims} mean((x's neighbour differences along d)²) and return
    that value (slab differences per axis, no autograd graph; ``x`` and ``gx`` of one shape)."""
    total = 0.0
    for d in dims:
        n = x.shape[d]
        if n < 2:
            continue
        diff = x.narrow(d, 1, n - 1) - x.narrow(d, 0, n - 1)
        scale = w / diff.numel()
        flat = diff.reshape(-1)
        total += scale * float(torch.dot(flat, flat))
        diff.mul_(2.0 * scale)
        gx.narrow(d, 1, n - 1).add_(diff)
        gx.narrow(d, 0, n - 1).sub_(diff)
    return total


def vm_dims(extent: np.ndarray, voxels: int) -> tuple[int, int, int]:
    """(R_x, R_y, R_z) corner counts of a dense grid of about ``voxels`` cubic voxels over ``extent`` (3,)."""
    z, y, x = grid_shape(extent, voxels)
    return x, y, z


def make_vm(dims: tuple[int, int, int], density: int, colour: int, channels: int, scale: float,
            device: torch.device) -> VMFactors:  # fmt: skip
    """New factors (leaves) at corner counts ``dims``: ``density`` and ``colour`` channels (``density`` 0: no density
    factors) at ``scale`` × N(0, 1), the basis (channels, 3·colour) uniform in ±1/√(3·colour) (``nn.Linear``'s
    weight); torch's global generator."""

    def planes(ch: int) -> list[Tensor]:
        if ch == 0:
            return []
        return [(scale * torch.randn((1, ch, dims[b], dims[a]))).to(device).requires_grad_(True) for a, b in PLANE_AXES]

    def lines(ch: int) -> list[Tensor]:
        if ch == 0:
            return []
        return [(scale * torch.randn((1, ch, dims[c], 1))).to(device).requires_grad_(True) for c in LINE_AXES]

    bound = 1.0 / math.sqrt(3 * colour)
    basis = ((torch.rand((channels, 3 * colour)) * 2 - 1) * bound).to(device).requires_grad_(True)
    return VMFactors(planes(density), lines(density), planes(colour), lines(colour), basis)


@torch.no_grad()
def grow_vm(vm: VMFactors, dims: tuple[int, int, int]) -> VMFactors:
    """The factors resampled (bilinear / linear, corners aligned) to corner counts ``dims`` (new leaves; the basis
    kept)."""

    def up_planes(ps: list[Tensor]) -> list[Tensor]:
        return [F.interpolate(p.detach(), size=(dims[b], dims[a]), mode="bilinear", align_corners=True)
                .contiguous().requires_grad_(True) for p, (a, b) in zip(ps, PLANE_AXES, strict=False)]  # fmt: skip

    def up_lines(ls: list[Tensor]) -> list[Tensor]:
        return [F.interpolate(q.detach(), size=(dims[c], 1), mode="bilinear", align_corners=True)
                .contiguous().requires_grad_(True) for q, c in zip(ls, LINE_AXES, strict=False)]  # fmt: skip

    return VMFactors(up_planes(vm.density_planes), up_lines(vm.density_lines), up_planes(vm.colour_planes),
                     up_lines(vm.colour_lines), vm.basis)  # fmt: skip


@torch.no_grad()
def vm_tv_grad_(vm: VMFactors, w_density: float, w_colour: float) -> float:
    """Add to the factors' ``.grad`` (created when missing) the gradient of w · Σ_factors (mean squared neighbour
    differences averaged over the factor's axes), w = ``w_density`` / ``w_colour``; returns the weighted value."""
    total = 0.0
    for ts, w in (([*vm.density_planes, *vm.density_lines], w_density),
                  ([*vm.colour_planes, *vm.colour_lines], w_colour)):  # fmt: skip
        if w <= 0:
            continue
        for x in ts:
            if x.grad is None:
                x.grad = torch.zeros_like(x)
            dims = [d for d in (2, 3) if x.shape[d] > 1]
            total += tv_grad_(x, x.grad, w / len(dims), dims)
    return total


def vm_arrays(vm: VMFactors) -> VMArrays:
    """The factors as stored (:class:`eigs.artifacts.field.VMArrays`)."""

    def planes(ps: list[Tensor]) -> list[np.ndarray]:
        return [p.detach()[0].cpu().numpy().astype(np.float32) for p in ps]

    def lines(ls: list[Tensor]) -> list[np.ndarray]:
        return [q.detach()[0, :, :, 0].cpu().numpy().astype(np.float32) for q in ls]

    return VMArrays(planes(vm.density_planes), lines(vm.density_lines), planes(vm.colour_planes),
                    lines(vm.colour_lines), vm.basis.detach().cpu().numpy().astype(np.float32))  # fmt: skip


def vm_from_leaves(ts: list[Tensor], density: bool) -> VMFactors:
    """Factors from :meth:`VMFactors.leaves`' list (with or without the density factors)."""
    if density:
        return VMFactors(ts[0:3], ts[3:6], ts[6:9], ts[9:12], ts[12])
    return VMFactors([], [], ts[0:3], ts[3:6], ts[6])
