"""The gradient of a voxel grid's total variation, added in place: Σ_groups w · Σ_axes mean((differences of
neighbouring voxels along the axis, over the group's channels)²), Plenoxels' smoothness prior on a field's raw grid.

:func:`grid_tv_grad_` takes the grid channels last, (Z, Y, X, C) contiguous (the layout the field trains in,
:mod:`eigs.train.field.model`): on float32 CPU tensors one pass of a kernel (``csrc/grid_tv.cpp``), elsewhere
:func:`grid_tv_grad_reference_`'s tensor ops. Both give each gradient entry the same float32 operations in the same
order (tests/train/test_field_model.py, bit for bit); the kernel sums the value in float64, the reference in float32.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import torch
from torch import Tensor

from eigs.util.extension import load_extension

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("grid_tv.cpp",)


def load() -> ModuleType:
    """The compiled kernel (built on first use, cached)."""
    return load_extension("eigs_grid_tv", CSRC, SOURCES, (), "the grid total-variation kernel")


def _live(groups: list[tuple[int, int, float]]) -> list[tuple[int, int, float]]:
    return [(a, b, w) for a, b, w in groups if w > 0 and b > a]


@torch.no_grad()
def grid_tv_grad_(x: Tensor, gx: Tensor, groups: list[tuple[int, int, float]]) -> float:
    """Add to ``gx`` the gradient of the total variation of ``x`` (both (Z, Y, X, C), contiguous) over the channel
    groups ``(first, stop, w)`` (channels first ≤ c < stop, weight w; a group of weight 0 leaves its channels
    untouched) and return its value: Σ_groups w · Σ_axes mean((x[i+1] − x[i])² along the axis, the group's channels)."""
    live = _live(groups)
    if not live:
        return 0.0
    kernel = (x.dtype == gx.dtype == torch.float32 and x.device.type == gx.device.type == "cpu"
              and x.is_contiguous() and gx.is_contiguous() and x.dim() == 4)  # fmt: skip
    if not kernel:
        return grid_tv_grad_reference_(x, gx, groups)
    c = int(x.shape[3])
    spatial = [int(n) for n in x.shape[:3]]
    twice = torch.zeros((3, c), dtype=torch.float32)
    mask = torch.zeros(c, dtype=torch.uint8)
    for d, n in enumerate(spatial):
        if n < 2:
            continue
        others = spatial[0] * spatial[1] * spatial[2] // n
        for a, b, w in live:
            twice[d, a:b] = 2.0 * w / ((n - 1) * others * (b - a))  # rounded to float32 as the reference rounds it
    for a, b, _ in live:
        mask[a:b] = 1
    return float(load().grid_tv_grad(x, gx, twice, mask))


def grid_tv_grad_reference_(x: Tensor, gx: Tensor, groups: list[tuple[int, int, float]]) -> float:
    """:func:`grid_tv_grad_` in tensor ops (its reference): every channel of a group with w > 0 gets the same
    operations in the same order as the field's per-slice ``tv_grad_`` on that group alone (difference, times
    2·scale rounded to the grid's dtype, added to the later neighbour and subtracted from the earlier, axis by axis),
    so the gradients are equal bit for bit; all channels go through each operation at once on contiguous blocks."""
    live = _live(groups)
    if not live:
        return 0.0
    lo, hi = min(a for a, _, _ in live), max(b for _, b, _ in live)
    if sum(b - a for a, b, _ in live) != hi - lo:  # groups with gaps between them: one at a time
        return sum(grid_tv_grad_reference_(x, gx, [g]) for g in live)
    x, gx = x[..., lo:hi], gx[..., lo:hi]  # the whole grid (no copy) when every channel is live
    total = 0.0
    for d in (0, 1, 2):
        n = x.shape[d]
        if n < 2:
            continue
        diff = x.narrow(d, 1, n - 1) - x.narrow(d, 0, n - 1)  # (…, C') contiguous
        twice = torch.empty(hi - lo, dtype=x.dtype)
        for a, b, w in live:
            twice[a - lo : b - lo] = 2.0 * w / diff[..., a - lo : b - lo].numel()  # rounded as mul_ rounds it
        scaled = diff * twice.to(diff.device)
        total += 0.5 * float(torch.dot(diff.reshape(-1), scaled.reshape(-1)))  # Σ_c scale_c · Σ diff_c²
        gx.narrow(d, 1, n - 1).add_(scaled)
        gx.narrow(d, 0, n - 1).sub_(scaled)
    return total
