"""The field model's pieces without training: the in-place total-variation gradient against autograd of the
TV formula in float64, the warp's grid (finer core corners, seeding through the warp), the default budgets."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eigs.train.catalog import METHODS, field_methods
from eigs.train.config import TrainConfig
from eigs.train.field.model import FieldModel, warp_np
from eigs.train.field.options import FieldOptions
from eigs.train.resolve import train_config


def _model(opts: FieldOptions, points=None, colours=None) -> FieldModel:
    lo, hi = np.array([-2.0, -2.0, -1.0]), np.array([2.0, 2.0, 0.8])
    return FieldModel(lo, hi, 3, opts, torch.device("cpu"), points=points, colours=colours)


@pytest.mark.parametrize("layout", [torch.contiguous_format, torch.channels_last_3d])
def test_in_place_tv_gradient_matches_autograd_of_the_tv_formula(layout):
    """Both layouts: channels last (the training grid's, grid_tv_grad_) and contiguous (tv_grad_)."""
    m = _model(FieldOptions(voxels_start=9 * 10 * 6, core_ratio=1.0, init_from_points=False))
    g = torch.Generator().manual_seed(0)
    grid = torch.randn(m.grid.shape, generator=g, dtype=torch.float64).contiguous(memory_format=layout)
    base = torch.randn(m.grid.shape, generator=g, dtype=torch.float64).contiguous(memory_format=layout)  # data term
    w_d, w_c = 0.3, 0.07
    # reference: autograd of w_d · TV(density) + w_c · TV(colour) in float64 (mean squared neighbour differences)
    ref_grid = grid.clone().requires_grad_(True)
    m.grid = ref_grid
    tv_d, tv_c = m.total_variation()
    ref_value = w_d * tv_d + w_c * tv_c
    ref_value.backward()
    m.grid = grid.clone().requires_grad_(True)
    m.grid.grad = base.clone()
    value = m.add_total_variation_grad(w_d, w_c)
    torch.testing.assert_close(m.grid.grad, base + ref_grid.grad, rtol=1e-12, atol=1e-12)
    ref = float(ref_value.detach())
    assert abs(value - ref) <= 1e-12 * max(1.0, abs(ref))
    # zero weights add nothing
    m.grid.grad = base.clone()
    assert m.add_total_variation_grad(0.0, 0.0) == 0.0
    torch.testing.assert_close(m.grid.grad, base, rtol=0, atol=0)


def test_core_grid_is_finer_and_seeding_goes_through_the_warp():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-0.3, -0.3, -0.6], [0.3, 0.3, 0.2], size=(300, 3))  # an object near the origin
    cols = rng.uniform(0.2, 0.8, size=(300, 3))
    o = FieldOptions(voxels_start=40_000, core_ratio=3.0, core_radius=1.0, box_quantile=0.0, box_margin=0.0)
    m = _model(o, pts, cols)
    assert m.warp is not None
    z, y, x = m.grid.shape[2:]
    # a grid of about the same corner count without the core has coarser voxels (here about 2×)
    u = _model(FieldOptions(voxels_start=40_000, core_ratio=1.0, init_from_points=False))
    assert u.warp is None and 1.8 < u.voxel_size() / m.voxel_size() < 3.0
    # the core's corner spacing (world units) is the axis' extent in core units / (n − 1): the model's voxel size
    # up to the rounding of the corner counts
    for a, n in enumerate((x, y, z)):
        corners = np.interp(np.linspace(0, 1, n), m.warp[1, a], m.warp[0, a])
        inside = (corners > pts[:, a].min() + 0.05) & (corners < pts[:, a].max() - 0.05)
        step = np.diff(corners)[inside[:-1] & inside[1:]]
        np.testing.assert_allclose(step, m.extent[a] / (n - 1), rtol=1e-9)
        np.testing.assert_allclose(step, m.voxel_size(), rtol=0.05)
    # every point's nearest corner (through the warp) was seeded dense
    idx = np.round(warp_np(m.warp, m.lo_np, m.hi_np, pts) * (np.array([x, y, z]) - 1)).astype(int)
    raw = m.grid.detach()[0, 0].numpy()[idx[:, 2], idx[:, 1], idx[:, 0]]
    assert np.all(raw > 0) and float((m.grid.detach()[0, 0] > 0).float().mean()) < 0.5


def test_every_field_method_has_a_default_budget_that_eigs_train_uses():
    assert field_methods() == {"nerf", "deblur-nerf", "edi-nerf", "e2nerf"}
    for m in field_methods():
        assert train_config({"method": m}).steps == METHODS[m].steps == 800
        assert train_config({"method": m, "steps": 77}).steps == 77  # the run's own steps win
        assert train_config({"method": m}, steps=12).steps == 12  # --steps wins
        assert train_config({}, method_name=m).steps == 800  # --method with the method's budget
    assert train_config({"method": "3dgs"}).steps == TrainConfig().steps == METHODS["3dgs"].steps


@pytest.mark.parametrize(("w_d", "w_c"), [(1e-2, 1e-3), (0.0, 1e-3), (1e-2, 0.0)])
def test_channels_last_tv_gradient_is_the_per_slice_gradient_bit_for_bit(w_d, w_c):
    """float32, as training runs: the channels-last path gives the contiguous path's gradient exactly (the same
    float32 operations per entry) and its value to float32 rounding; a zero weight leaves its channels untouched."""
    m = _model(FieldOptions(voxels_start=11 * 9 * 7, core_ratio=1.0, init_from_points=False))
    g = torch.Generator().manual_seed(1)
    grid = torch.randn(m.grid.shape, generator=g)
    base = torch.randn(m.grid.shape, generator=g)
    out = {}
    for layout in (torch.contiguous_format, torch.channels_last_3d):
        m.grid = grid.clone(memory_format=layout).requires_grad_(True)
        m.grid.grad = base.clone(memory_format=layout)
        out[layout] = (m.add_total_variation_grad(w_d, w_c), m.grid.grad.contiguous())
    (v_plain, g_plain), (v_last, g_last) = out.values()
    assert torch.equal(g_plain, g_last)
    assert abs(v_last - v_plain) <= 1e-6 * abs(v_plain)
    for ch, w in ((slice(0, 1), w_d), (slice(1, None), w_c)):
        assert torch.equal(g_last[:, ch], base[:, ch]) == (w == 0.0)


@pytest.mark.parametrize("groups", [[(0, 1, 1e-2 / 3), (1, 4, 1e-3 / 3)], [(0, 1, 0.0), (1, 4, 0.3)],
                                    [(0, 1, 0.2), (1, 2, 0.0), (2, 4, 0.1)], [(0, 4, 0.0)]])  # fmt: skip
@pytest.mark.parametrize("threads", [1, 2])
def test_grid_tv_kernel_equals_its_tensor_op_reference_bit_for_bit(groups, threads):
    """The kernel against grid_tv_grad_reference_ on a channels-last float32 grid with an existing gradient: the same
    gradient bit for bit (groups with zero weight, one with a gap between live groups, an axis of one voxel), the
    value to float32 rounding, at one and two threads."""
    from eigs.losses.grid_tv import grid_tv_grad_, grid_tv_grad_reference_

    g = torch.Generator().manual_seed(2)
    for shape in ((13, 9, 11, 4), (1, 7, 5, 4)):
        x = torch.randn(shape, generator=g)
        base = torch.randn(shape, generator=g)
        ref, got = base.clone(), base.clone()
        before = torch.get_num_threads()
        torch.set_num_threads(threads)
        try:
            v_ref = grid_tv_grad_reference_(x, ref, groups)
            v_got = grid_tv_grad_(x, got, groups)
        finally:
            torch.set_num_threads(before)
        assert torch.equal(got, ref), shape
        assert abs(v_got - v_ref) <= 1e-6 * max(abs(v_ref), 1e-30), shape
        if all(w == 0 for _, _, w in groups):
            assert v_got == 0.0 and torch.equal(got, base)
