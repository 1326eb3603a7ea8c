"""Event-integration loss (Eq. 9–10) and the intensity model it shares with EDI."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eigs.edi import edi
from eigs.losses.events import (
    LOG_EPS,
    e2nerf_event_loss,
    event_integration_loss,
    lin_log,
    linear_to_srgb,
    log_intensity,
    luma,
    srgb_to_linear,
)


def test_constants_and_transforms_agree_with_edi():
    assert LOG_EPS == edi.LOG_EPS
    rng = np.random.default_rng(0)
    img = rng.random((4, 5, 3))
    np.testing.assert_allclose(luma(torch.from_numpy(img)).numpy(), edi.luma(img), rtol=0, atol=1e-15)
    np.testing.assert_allclose(srgb_to_linear(torch.from_numpy(img)).numpy(), edi.srgb_to_linear(img), atol=1e-15)
    np.testing.assert_allclose(linear_to_srgb(torch.from_numpy(img)).numpy(), edi.linear_to_srgb(img), atol=1e-15)


def test_zero_when_renders_differ_by_exactly_c_times_the_counts():
    rng = np.random.default_rng(1)
    counts = torch.from_numpy(rng.integers(-4, 5, (6, 7))).to(torch.int32)
    c_pos, c_neg = 0.25, 0.2
    log_a = torch.from_numpy(rng.normal(-1, 0.3, (6, 7)))
    cd = counts.to(torch.float64)
    log_b = log_a + torch.where(counts >= 0, c_pos * cd, c_neg * cd)
    assert event_integration_loss(log_a, log_b, counts, c_pos, c_neg) < 1e-12
    # per-pixel maps
    cp = torch.from_numpy(rng.uniform(0.15, 0.3, (6, 7)))
    cn = torch.from_numpy(rng.uniform(0.15, 0.3, (6, 7)))
    log_b = log_a + torch.where(counts >= 0, cp * counts, cn * counts)
    assert event_integration_loss(log_a, log_b, counts, cp, cn) < 1e-12
    # an error of one event on one unmasked pixel out of 42 → 1/42; masked pixels do not count
    log_b2 = log_b.clone()
    log_b2[0, 0] += 100 * max(cp[0, 0], cn[0, 0])
    mask = torch.zeros(6, 7, dtype=torch.bool)
    assert event_integration_loss(log_a, log_b2, counts, cp, cn, mask) > 1.0
    mask[0, 0] = True
    assert event_integration_loss(log_a, log_b2, counts, cp, cn, mask) < 1e-12


def test_a_stack_of_intervals_is_the_mean_of_their_losses():
    """K intervals in one call (per-pixel thresholds and mask shared) equal the mean of the K single calls; with one
    pixel of one interval off by 3 events and nothing else wrong, the stack's loss is 3 / (K · unmasked pixels)."""
    rng = np.random.default_rng(4)
    logs = torch.from_numpy(rng.normal(-1, 0.3, (5, 6, 7)))  # L = 5 latent log images
    counts = torch.from_numpy(rng.integers(-4, 5, (4, 6, 7))).to(torch.int32)  # the K = 4 intervals' net counts
    cp = torch.from_numpy(rng.uniform(0.15, 0.3, (6, 7)))
    cn = torch.from_numpy(rng.uniform(0.15, 0.3, (6, 7)))
    mask = torch.from_numpy(rng.random((6, 7)) < 0.2)
    for dz, mm in ((0.0, 0.0), (0.3, 0.05)):
        each = [event_integration_loss(logs[k], logs[k + 1], counts[k], cp, cn, mask, dz, mm) for k in range(4)]
        stacked = event_integration_loss(logs[:-1], logs[1:], counts, cp, cn, mask, dz, mm)
        torch.testing.assert_close(stacked, torch.stack(each).mean(), rtol=1e-14, atol=0)
    exact = [logs[0]]
    for k in range(4):
        e = counts[k].to(torch.float64)
        exact.append(exact[-1] + torch.where(e >= 0, cp * e, cn * e))
    exact = torch.stack(exact)
    assert event_integration_loss(exact[:-1], exact[1:], counts, cp, cn, mask) < 1e-12
    i, j = map(int, (~mask).nonzero()[0])
    off = counts.clone()
    off[2, i, j] += 3
    expected = 3 / (4 * int((~mask).sum()))
    torch.testing.assert_close(event_integration_loss(exact[:-1], exact[1:], off, cp, cn, mask),
                               torch.tensor(expected, dtype=torch.float64), rtol=1e-12, atol=0)  # fmt: skip


def test_log_intensity_model_and_its_gradient_stay_finite_at_zero():
    img = torch.zeros(3, 4, 3, dtype=torch.float64, requires_grad=True)
    out = log_intensity(img, "srgb")
    assert torch.allclose(out, torch.full_like(out, np.log(LOG_EPS)))
    out.sum().backward()
    assert torch.isfinite(img.grad).all()


def test_lin_log_is_continuous_at_the_knee_and_e2nerf_loss_zero_at_its_target():
    x = torch.tensor([19.999999, 20.0, 20.000001], dtype=torch.float64)
    y = lin_log(x)
    assert (y[2] - y[0]).abs() < 1e-6
    # renders whose lin-log differences equal 0.3·(E + 0.5) on rising pixels: the positive term vanishes
    e = torch.tensor([[1, 2]], dtype=torch.int32)
    cum = torch.stack([torch.zeros_like(e), e])  # (2, 1, 2)
    logs = torch.stack([torch.zeros(1, 2, dtype=torch.float64), 0.3 * (e.double() + 0.5)])
    assert e2nerf_event_loss(logs, cum) < 1e-20


def test_noise_aware_event_loss_forgives_exactly_the_stated_tolerance():
    """deadzone + mismatch·|E| events of error cost nothing; beyond it the excess is L1 (closed form)."""
    counts = torch.tensor([[0, 2, -4, 10]], dtype=torch.int32)
    c = 0.25
    log_a = torch.zeros(1, 4, dtype=torch.float64)
    errors = torch.tensor([[0.4, -0.7, 0.9, 2.0]], dtype=torch.float64)  # in events
    log_b = c * (counts.to(torch.float64) + errors)
    dz, mm = 0.5, 0.1
    tol = dz + mm * counts.abs().to(torch.float64)  # 0.5, 0.7, 0.9, 1.5
    want = (errors.abs() - tol).clamp_min(0).mean()  # 0, 0, 0, 0.5 → 0.125
    got = event_integration_loss(log_a, log_b, counts, c, c, deadzone=dz, mismatch=mm)
    assert abs(float(got) - float(want)) < 1e-12 and abs(float(want) - 0.125) < 1e-12
    # the defaults are the paper's L1
    assert abs(float(event_integration_loss(log_a, log_b, counts, c, c)) - float(errors.abs().mean())) < 1e-12


@pytest.mark.parametrize("masked", [False, True])
@pytest.mark.parametrize("maps", [False, True])
@pytest.mark.parametrize(("renders", "h", "w"), [(2, 1, 1), (5, 17, 23), (9, 40, 33)])
def test_fused_event_loss_over_renders_has_the_slices_gradient_bit_for_bit(masked, maps, renders, h, w):
    """event_loss_over_renders (the fused kernel) against event_integration_loss on the slices of the same logs: the
    gradient identical (the same float32 operations), the loss within float32 summation order; some intervals with
    no change and an exact match (the L1's subgradient 0)."""
    from eigs.losses.fused_events import event_loss_over_renders

    g = torch.Generator().manual_seed(renders * h + int(masked) + 2 * int(maps))
    logs0 = torch.randn(renders, h, w, generator=g)
    logs0[1] = logs0[0]  # no change over the first interval
    cum = torch.randint(-3, 4, (renders, h, w), generator=g).cumsum(0).to(torch.int32)
    c_pos = 0.2 + 0.05 * torch.rand(h, w, generator=g) if maps else 0.21
    c_neg = 0.2 + 0.05 * torch.rand(h, w, generator=g) if maps else 0.19
    if renders > 2:  # one pixel whose second interval matches its count exactly: |r| = 0
        cum[2, 0, 0] = cum[1, 0, 0] + 2
        logs0[2, 0, 0] = logs0[1, 0, 0] + 2 * (c_pos if not maps else c_pos[0, 0].item())
    mask = torch.rand(h, w, generator=g) < 0.3 if masked else None
    got_x = logs0.clone().requires_grad_()
    got = event_loss_over_renders(got_x, cum, c_pos, c_neg, mask)
    (-1.7 * got).backward()
    ref_x = logs0.clone().requires_grad_()
    ref = event_integration_loss(ref_x[:-1], ref_x[1:], cum[1:] - cum[:-1], c_pos, c_neg, mask)
    (-1.7 * ref).backward()
    assert torch.equal(got_x.grad, ref_x.grad), (got_x.grad - ref_x.grad).abs().max()
    assert got.dtype == torch.float32 and got.shape == ()
    assert abs(got.item() - ref.item()) <= 1e-6 * max(1.0, abs(ref.item()))


def test_fused_event_loss_edges_and_fallback():
    """Every pixel masked: 0 with a zero gradient, as the tensor ops; the dead zone, float64 and int64 counts take the
    tensor ops (the same function's result); a NaN log gives a NaN loss, never a silent number."""
    from eigs.losses.fused_events import event_loss_over_renders

    logs = torch.randn(3, 4, 5, requires_grad=True)
    cum = torch.zeros(3, 4, 5, dtype=torch.int32)
    out = event_loss_over_renders(logs, cum, 0.2, 0.2, torch.ones(4, 5, dtype=torch.bool))
    out.backward()
    assert out.item() == 0.0 and torch.equal(logs.grad, torch.zeros_like(logs))
    for kwargs, lg, cc in (({"deadzone": 0.5}, logs.detach(), cum), ({}, logs.detach().double(), cum),
                           ({}, logs.detach(), cum.long())):  # fmt: skip
        ref = event_integration_loss(lg[:-1], lg[1:], cc[1:] - cc[:-1], 0.2, 0.2, None, **kwargs)
        assert torch.equal(event_loss_over_renders(lg, cc, 0.2, 0.2, None, **kwargs), ref)
    bad = logs.detach().clone()
    bad[1, 2, 3] = float("nan")
    assert torch.isnan(event_loss_over_renders(bad, cum, 0.2, 0.2))
