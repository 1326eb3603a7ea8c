"""The field's trilinear kernel (eigs.render.trilinear) against grid_sample in float64 (its reference): values and
both gradients with random cotangents, the border (points on and beyond the box's faces, a grid one voxel thick),
two thread counts, and the fallback to the reference off the kernel's dtype."""

from __future__ import annotations

import pytest
import torch

from eigs.render.trilinear import trilinear, trilinear_reference


def case(c: int, dims: tuple[int, int, int], n: int, seed: int, spread: float = 1.0):
    g = torch.Generator().manual_seed(seed)
    grid = torch.randn((1, c, *dims), generator=g, dtype=torch.float64)
    u = 0.5 + spread * (torch.rand((n, 3), generator=g, dtype=torch.float64) - 0.5)
    return grid, u


def grads(fn, grid, u, v):
    grid = grid.clone().requires_grad_()
    u = u.clone().requires_grad_()
    out = fn(grid, u)
    v_grid, v_u = torch.autograd.grad(out, (grid, u), v)
    return out.detach(), v_grid, v_u


@pytest.mark.parametrize(("c", "dims", "spread"), [(4, (9, 7, 11), 1.0), (1, (5, 6, 4), 1.3), (3, (1, 4, 5), 0.9)])
@pytest.mark.parametrize("threads", [1, 2])
def test_values_and_gradients_match_grid_sample_in_float64(c, dims, spread, threads) -> None:
    grid, u = case(c, dims, 3000, seed=c + dims[0], spread=spread)
    u[:4] = torch.tensor([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [1.0, 0.5, 0.0], [0.5, 0.25, 0.75]], dtype=u.dtype)
    v = torch.randn((len(u), c), generator=torch.Generator().manual_seed(3), dtype=torch.float64)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        ref = grads(trilinear_reference, grid, u.clamp(0, 1), v)
        got = grads(trilinear, grid.float(), u.clamp(0, 1).float(), v.float())
    finally:
        torch.set_num_threads(before)
    for name, a, b in zip(("value", "v_grid", "v_u"), got, ref, strict=True):
        scale = max(b.abs().max().item(), 1.0)
        assert (a.double() - b).abs().max().item() <= 2e-5 * scale, name


def test_only_the_asked_gradient_is_computed_and_the_reference_runs_off_float32() -> None:
    grid, u = case(2, (4, 4, 4), 50, seed=1)
    g32 = grid.float().requires_grad_()
    out = trilinear(g32, u.float())  # points without gradient
    (v_grid,) = torch.autograd.grad(out.sum(), (g32,))
    assert torch.allclose(v_grid.sum(), torch.tensor(float(len(u) * 2)), rtol=1e-5)  # the weights sum to 1
    assert torch.equal(trilinear(grid, u), trilinear_reference(grid, u))  # float64: grid_sample itself
