"""Motion-consistency loss (paper Eq. 3–6): twist fit against closed forms, degenerate inputs, gradients."""

from __future__ import annotations

import pytest
import torch

from eigs.losses.consistency import (
    fit_twist,
    motion_consistency_loss,
    motion_consistency_loss_reference,
    rigid_displacement,
)

F64 = torch.float64


def _field(n: int, seed: int = 0, scale: float = 1.0, shift: float = 3.0):
    g = torch.Generator().manual_seed(seed)
    x = (torch.randn(n, 3, generator=g, dtype=F64) + shift) * scale
    omega = torch.randn(3, generator=g, dtype=F64) * 0.02
    nu = torch.randn(3, generator=g, dtype=F64) * 0.1
    return x, omega, nu, g


def test_noise_free_twist_is_recovered_and_loss_is_zero():
    x, omega, nu, _ = _field(500)
    dx = rigid_displacement(x, omega, nu)
    w, v = fit_twist(x, dx, reg=0.0)
    assert torch.allclose(w, omega, atol=1e-12, rtol=0) and torch.allclose(v, nu, atol=1e-12, rtol=0)
    w, v = fit_twist(x, dx)  # the default (small) regulariser
    assert (w - omega).abs().max() < 1e-6 and (v - nu).abs().max() < 1e-6
    assert motion_consistency_loss(x, dx, reg=0.0) < 1e-20


def test_eq3_matches_the_expanded_rows_of_eq4():
    x, omega, nu, _ = _field(10)
    d = rigid_displacement(x, omega, nu)
    wx, wy, wz = omega
    expected = torch.stack([
        x[:, 1] * wz - x[:, 2] * wy - nu[0],
        x[:, 2] * wx - x[:, 0] * wz - nu[1],
        x[:, 0] * wy - x[:, 1] * wx - nu[2],
    ], dim=1)  # fmt: skip
    torch.testing.assert_close(d, expected, rtol=0, atol=1e-15)


def test_matches_dense_least_squares_with_noise_and_outliers():
    x, omega, nu, g = _field(400, seed=3)
    dx = rigid_displacement(x, omega, nu) + 1e-3 * torch.randn(400, 3, generator=g, dtype=F64)
    out = torch.randperm(400, generator=g)[:40]
    dx[out] += torch.randn(40, 3, generator=g, dtype=F64)  # 10 % outliers
    reg = 1e-3
    # the dense system of Eq. 5, formed explicitly (3N × 6) as an independent reference
    a = torch.zeros(3 * 400, 6, dtype=F64)
    for j in range(400):
        xj, yj, zj = x[j]
        a[3 * j : 3 * j + 3] = torch.tensor(
            [[0, -zj, yj, -1, 0, 0], [zj, 0, -xj, 0, -1, 0], [-yj, xj, 0, 0, 0, -1]], dtype=F64
        )
    ref = torch.linalg.solve(a.T @ a + reg * 400 * torch.eye(6, dtype=F64), a.T @ dx.reshape(-1))
    w, v = fit_twist(x, dx, reg=reg)
    torch.testing.assert_close(torch.cat([w, v]), ref, rtol=1e-9, atol=1e-12)
    # Huber keeps the outliers from dominating: inliers' residuals stay near the noise level
    loss = motion_consistency_loss(x, dx, reg=reg)
    assert torch.isfinite(loss) and loss > 0


@pytest.mark.parametrize("case", ["one", "collinear", "coplanar", "zero-displacement", "huge-coordinates", "empty"])
def test_degenerate_inputs_stay_finite(case):
    x, omega, nu, _ = _field(50)
    if case == "one":
        x = x[:1]
    elif case == "collinear":
        x = torch.zeros(50, 3, dtype=F64)
        x[:, 0] = torch.linspace(-1, 1, 50, dtype=F64)
    elif case == "coplanar":
        x[:, 2] = 0.5
    elif case == "huge-coordinates":
        x = x * 1e6
    elif case == "empty":
        x = x[:0]
    dx = torch.zeros_like(x) if case == "zero-displacement" else rigid_displacement(x, omega, nu)
    for dtype in (torch.float32, F64):
        xx, dd = x.to(dtype), dx.to(dtype).requires_grad_(True)
        w, v = fit_twist(xx, dd)
        assert torch.isfinite(w).all() and torch.isfinite(v).all()
        loss = motion_consistency_loss(xx, dd)
        loss.backward()
        assert torch.isfinite(loss) and torch.isfinite(dd.grad).all()
        if case in ("one", "collinear", "coplanar"):  # the fitted field still explains the displacements
            assert loss < 1e-6
        if case == "zero-displacement":
            assert w.abs().max() == 0 and v.abs().max() == 0


def test_gradient_through_the_fit_is_optional_and_tested_against_finite_differences():
    x, omega, nu, g = _field(30, seed=5)
    dx = (rigid_displacement(x, omega, nu) + 0.05 * torch.randn(30, 3, generator=g, dtype=F64)).requires_grad_(True)
    for through in (True, False):
        f = lambda d, t=through: motion_consistency_loss(x, d, reg=1e-4, delta=0.1, grad_through_fit=t)  # noqa: E731
        if through:
            assert torch.autograd.gradcheck(f, (dx,), eps=1e-6, atol=1e-6)
        else:
            # detached fit: the gradient is that of the Huber term with the fitted field held fixed
            w, v = fit_twist(x, dx.detach(), reg=1e-4)
            fixed = rigid_displacement(x, w, v)
            ref = torch.autograd.grad(torch.nn.functional.huber_loss(dx, fixed, reduction="sum", delta=0.1) / 30, dx)[0]
            got = torch.autograd.grad(f(dx), dx)[0]
            torch.testing.assert_close(got, ref)


def test_a_stack_of_fields_is_fitted_each_against_its_own_twist():
    """K fields at the same points in one call (the normal matrix shared): each recovers its own closed-form twist,
    and the loss is the mean of the K single-field losses (float64)."""
    x, _, _, g = _field(400, seed=3)
    twists = [(torch.randn(3, generator=g, dtype=F64) * 0.02, torch.randn(3, generator=g, dtype=F64) * 0.1)
              for _ in range(4)]  # fmt: skip
    fields = torch.stack([rigid_displacement(x, w, v) for w, v in twists])  # (K, N, 3)
    w, v = fit_twist(x, fields, reg=0.0)
    assert w.shape == v.shape == (4, 3)
    for k, (wk, vk) in enumerate(twists):
        assert torch.allclose(w[k], wk, atol=1e-12, rtol=0) and torch.allclose(v[k], vk, atol=1e-12, rtol=0)
    torch.testing.assert_close(rigid_displacement(x, w, v), fields, atol=1e-12, rtol=0)
    noisy = fields + 0.05 * torch.randn(fields.shape, generator=g, dtype=F64)
    one_by_one = torch.stack([motion_consistency_loss(x, noisy[k], delta=0.02) for k in range(4)]).mean()
    assert one_by_one > 1e-4
    torch.testing.assert_close(motion_consistency_loss(x, noisy, delta=0.02), one_by_one, atol=0, rtol=1e-12)
    assert fit_twist(x[:0], noisy[:, :0])[0].shape == (4, 3)  # no Gaussians: zero twists, one per field


@pytest.mark.parametrize("through", [True, False])
@pytest.mark.parametrize("dtype", [torch.float32, F64])
def test_the_fused_loss_equals_the_autograd_reference(through, dtype):
    """motion_consistency_loss (one autograd Function, the gradient through the fit as the fit of the Huber term's
    gradient) against motion_consistency_loss_reference (autograd through every op): the same loss and the same
    gradient for a random cotangent, on K = 4 fields whose residuals fall on both sides of the Huber threshold."""
    x, _, _, g = _field(2000, seed=11)
    twists = [(torch.randn(3, generator=g, dtype=F64) * 0.02, torch.randn(3, generator=g, dtype=F64) * 0.1)
              for _ in range(4)]  # fmt: skip
    fields = torch.stack([rigid_displacement(x, w, v) for w, v in twists])
    noise = torch.randn(fields.shape, generator=g, dtype=F64) * torch.rand(2000, 1, generator=g, dtype=F64) * 0.3
    dx = (fields + noise).to(dtype)
    xs = x.to(dtype)
    cot = torch.randn((), generator=g, dtype=F64).to(dtype) + 2.0
    got_dx, ref_dx = dx.clone().requires_grad_(True), dx.clone().requires_grad_(True)
    got = motion_consistency_loss(xs, got_dx, reg=1e-4, delta=0.1, grad_through_fit=through)
    ref = motion_consistency_loss_reference(xs, ref_dx, reg=1e-4, delta=0.1, grad_through_fit=through)
    (got * cot).backward()
    (ref * cot).backward()
    assert (noise.abs() > 0.1).any() and (noise.abs() < 0.1).any()  # both branches of the Huber loss
    tol = {"rtol": 1e-5, "atol": 1e-9} if dtype == torch.float32 else {"rtol": 1e-12, "atol": 1e-16}
    torch.testing.assert_close(got, ref, **tol)
    torch.testing.assert_close(got_dx.grad, ref_dx.grad, **tol)


def test_the_fused_loss_takes_one_field_and_no_gaussians():
    x, omega, nu, g = _field(50, seed=2)
    dx = (rigid_displacement(x, omega, nu) + 0.05 * torch.randn(50, 3, generator=g, dtype=F64)).requires_grad_(True)
    torch.testing.assert_close(motion_consistency_loss(x, dx), motion_consistency_loss_reference(x, dx), rtol=1e-12,
                               atol=0)  # fmt: skip
    empty = torch.zeros(0, 3, dtype=F64, requires_grad=True)
    loss = motion_consistency_loss(x[:0], empty)
    loss.backward()
    assert loss.item() == 0.0 and empty.grad.shape == (0, 3)
