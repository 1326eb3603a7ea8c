"""Trilinear interpolation of the field's voxel grid as one CPU kernel with its backward (``volume_csrc/``).

:func:`trilinear` returns what ``F.grid_sample(grid, 2u - 1, mode="bilinear", padding_mode="border",
align_corners=True)`` returns for a ``(1, C, D, H, W)`` grid and points ``u`` ``(N, 3)`` in [0, 1], reshaped to
``(N, C)``: the kernel on float32 CPU tensors, grid_sample (the reference) otherwise. Differentiable in the grid and
the points. Measured in docs/benchmarks.md ("The field's trilinear interpolation").
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import torch
import torch.nn.functional as F
from torch import Tensor
from torch.autograd.function import once_differentiable

from eigs.util.extension import load_extension

CSRC = Path(__file__).resolve().parent / "volume_csrc"
SOURCES = ("trilinear.cpp",)


def load() -> ModuleType:
    """The compiled kernel (built on first use, cached)."""
    return load_extension("eigs_trilinear", CSRC, SOURCES, (), "the trilinear interpolation kernel")


class _Trilinear(torch.autograd.Function):
    """grid (D, H, W, C) channels last, u (N, 3) -> (N, C)."""

    @staticmethod
    def forward(ctx, grid: Tensor, u: Tensor) -> Tensor:  # type: ignore[override]
        ctx.save_for_backward(grid, u)
        return load().trilinear_fwd(grid, u, -1)

    @staticmethod
    @once_differentiable
    def backward(ctx, v_out: Tensor) -> tuple[Tensor | None, Tensor | None]:  # type: ignore[override]
        grid, u = ctx.saved_tensors
        need_grid, need_u = ctx.needs_input_grad
        v_grid, v_u = load().trilinear_bwd(grid, u, v_out.contiguous(), need_grid, need_u)
        return (v_grid if need_grid else None), (v_u if need_u else None)


def trilinear_reference(grid: Tensor, u: Tensor) -> Tensor:
    """grid_sample's trilinear interpolation with border padding, aligned corners: grid (1, C, D, H, W), u (N, 3) in
    [0, 1] (x, y, z) -> (N, C)."""
    out = F.grid_sample(grid, (u * 2.0 - 1.0).reshape(1, 1, 1, -1, 3), mode="bilinear", padding_mode="border",
                        align_corners=True)  # fmt: skip
    return out.reshape(grid.shape[1], -1).T


def trilinear(grid: Tensor, u: Tensor, channels: int | None = None) -> Tensor:
    """Values (N, k) of the first k = ``channels`` (default: all C) channels of ``grid`` (1, C, D, H, W) at normalised
    points ``u`` (N, 3) in [0, 1] (x along W).

    The kernel reads the grid channels last: a grid stored so (``memory_format=torch.channels_last_3d``) is read in
    place and its gradient comes back in that layout, with no copy either way; any other grid is copied first (the
    training grid is kept channels last, :mod:`eigs.train.field.model`). Without autograd, the first k channels are
    read in place as well."""
    c = int(grid.shape[1])
    k = c if channels is None else channels
    if not 1 <= k <= c:
        raise ValueError(f"channels must lie in [1, {c}], got {channels}")
    cpu32 = (grid.device.type == "cpu" and u.device.type == "cpu" and grid.dtype == torch.float32
             and u.dtype == torch.float32 and grid.shape[0] == 1 and grid.numel() > 0)  # fmt: skip
    if not cpu32:
        return trilinear_reference(grid[:, :k], u)
    last = grid.permute(0, 2, 3, 4, 1)  # (1, D, H, W, C): a view, contiguous when the grid is channels last
    graph = torch.is_grad_enabled() and (grid.requires_grad or u.requires_grad)
    if k < c and (graph or not last.is_contiguous()):
        last = last[..., :k]  # copied below: the kernel's autograd takes whole grids
    last = last.contiguous().reshape(last.shape[1:])  # (D, H, W, C'): reshape of a contiguous tensor is a view
    if not graph:
        return load().trilinear_fwd(last, u.contiguous(), k if last.shape[-1] > k else -1)
    return _Trilinear.apply(last, u.contiguous())
