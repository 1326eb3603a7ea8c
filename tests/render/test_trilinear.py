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


def test_channels_last_grid_is_read_in_place_and_its_gradient_keeps_the_layout() -> None:
    """A channels-last grid (the training grid's layout) gives the same values and gradient as a contiguous one,
    bit for bit; its gradient comes back channels last (no copy), and the first-k-channels read without autograd
    equals the reference on those channels."""
    grid, u = case(4, (6, 5, 7), 400, seed=5)
    v = torch.randn((len(u), 4), generator=torch.Generator().manual_seed(4))
    plain = grid.float()
    last = plain.contiguous(memory_format=torch.channels_last_3d)
    assert not last.is_contiguous()
    out_plain, g_plain, _ = grads(trilinear, plain, u.float(), v)
    out_last, g_last, _ = grads(trilinear, last, u.float(), v)
    assert torch.equal(out_plain, out_last) and torch.equal(g_plain, g_last)
    leaf = last.clone().requires_grad_()
    trilinear(leaf, u.float()).backward(v)
    assert leaf.grad.is_contiguous(memory_format=torch.channels_last_3d)
    ref = trilinear_reference(grid[:, :1], u)
    with torch.no_grad():
        for g in (last, plain, leaf):  # in place (channels last) and copied (contiguous); with a grad-requiring leaf
            got = trilinear(g, u.float(), channels=1)
            assert got.shape == (len(u), 1)
            assert (got.double() - ref).abs().max().item() <= 2e-5 * max(ref.abs().max().item(), 1.0)
    got = trilinear(leaf, u.float(), channels=2)  # with autograd: the channels are sliced off, the gradient flows
    (v_leaf,) = torch.autograd.grad(got.sum(), (leaf,))
    assert v_leaf[:, 2:].abs().max().item() == 0.0 and v_leaf[:, :2].abs().max().item() > 0.0
    with pytest.raises(ValueError, match="channels"):
        trilinear(last, u.float(), channels=5)
