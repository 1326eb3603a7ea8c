"""Volume rendering (eigs.render.volume, eigs.render.field) against the float64 one-ray reference: forward and
backward, empty rays, rays that miss the grid, saturated and non-finite density, the occupancy packing."""

from __future__ import annotations

import math

import numpy as np
import torch

from eigs.render.field import FieldTensors, occupied, pixel_rays, query, render_rays
from eigs.render.volume import TAU_MAX, composite, ray_aabb
from eigs.render.volume_reference import composite_ray

# float32 batched renderer against the float64 reference: values in [0, 1], sums of ≤ 64 terms
RTOL, ATOL = 1e-4, 2e-6


def _rays(r: int = 12, s: int = 40, c: int = 3, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    sig = torch.rand((r, s), generator=g) * 20.0
    sig[sig < 6.0] = 0.0  # empty stretches between surfaces
    sig[0] = 0.0  # an empty ray
    sig[1, 5] = 1e4  # an opaque sample
    col = torch.rand((r, s, c), generator=g)
    delta = torch.rand((r, s), generator=g) * 0.05 + 1e-3
    bg = torch.rand(c, generator=g)
    return sig, col, delta, bg


def _reference(sig, col, delta, bg):
    out = [composite_ray(sig[i], col[i], delta[i], bg) for i in range(sig.shape[0])]
    return torch.stack([o[0] for o in out]), torch.stack([o[1] for o in out])


def test_forward_matches_the_float64_reference():
    sig, col, delta, bg = _rays()
    rgb, acc, w = composite(sig, col, delta, bg)
    ref_rgb, ref_acc = _reference(sig, col, delta, bg)
    torch.testing.assert_close(rgb.double(), ref_rgb, rtol=RTOL, atol=ATOL)
    torch.testing.assert_close(acc.double(), ref_acc, rtol=RTOL, atol=ATOL)
    torch.testing.assert_close(w.sum(1), acc, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(rgb[0], bg)  # an empty ray sees the background
    assert float(acc[0]) == 0.0
    # in float64 the batched formula (exp of a cumulative sum) equals the running product to rounding
    rgb64, acc64, _ = composite(sig.double(), col.double(), delta.double(), bg.double())
    torch.testing.assert_close(rgb64, ref_rgb, rtol=1e-12, atol=1e-13)


def test_backward_matches_the_float64_reference():
    sig, col, delta, bg = _rays(seed=1)
    sig = sig + 0.1  # no sample exactly at σ = 0 (the clamp's kink)
    sig[1, 5] = 5.0
    g = torch.Generator().manual_seed(7)
    probe = torch.rand((sig.shape[0], 3), generator=g, dtype=torch.float64)
    ins32 = [t.clone().requires_grad_(True) for t in (sig, col, delta, bg)]
    rgb, acc, _ = composite(*ins32)
    ((rgb.double() * probe).sum() + acc.double().sum()).backward()
    ins64 = [t.double().clone().requires_grad_(True) for t in (sig, col, delta, bg)]
    ref_rgb, ref_acc = _reference(*ins64)
    ((ref_rgb * probe).sum() + ref_acc.sum()).backward()
    for a, b, name in zip(ins32, ins64, ("sigma", "colour", "delta", "background"), strict=True):
        assert a.grad is not None and b.grad is not None
        torch.testing.assert_close(a.grad.double(), b.grad, rtol=5e-4, atol=1e-5, msg=name)


def test_saturated_and_non_finite_density_stay_finite():
    s = 16
    sig = torch.zeros((4, s))
    sig[0, 3] = float("inf")
    sig[1, 3] = float("nan")
    sig[2] = 1e38
    sig[3, 2] = 1e6
    col = torch.rand((4, s, 3), generator=torch.Generator().manual_seed(3))
    delta = torch.full((4, s), 0.02)
    ins = [t.clone().requires_grad_(True) for t in (sig, col, delta, torch.zeros(3))]
    rgb, acc, w = composite(*ins)
    (rgb.sum() + acc.sum()).backward()
    assert torch.isfinite(rgb).all() and torch.isfinite(acc).all()
    for t in ins:
        assert t.grad is not None and torch.isfinite(t.grad).all()
    # +inf and 1e38: opaque at the first such sample (α = 1 − e^{−TAU_MAX}); NaN: transparent
    torch.testing.assert_close(rgb[0], col[0, 3] * (1 - math.exp(-TAU_MAX)), rtol=1e-6, atol=1e-6)
    torch.testing.assert_close(rgb[2], col[2, 0] * (1 - math.exp(-TAU_MAX)), rtol=1e-6, atol=1e-6)
    assert float(acc[1].detach()) == 0.0
    ref, _ = composite_ray(sig[0], col[0], delta[0], torch.zeros(3))
    torch.testing.assert_close(rgb[0].double(), ref, rtol=1e-6, atol=1e-7)


def test_ray_box_intersection_closed_form():
    lo, hi = torch.tensor([-1.0, -2.0, -0.5]), torch.tensor([1.0, 2.0, 0.5])
    o = torch.tensor([[-3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 5.0, 0.0], [-3.0, 0.0, 0.0]])
    d = torch.tensor([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    tn, tf = ray_aabb(o, d, lo, hi, near=0.01)
    torch.testing.assert_close(tn[:2], torch.tensor([2.0, 0.01]))  # from outside; from inside (near)
    torch.testing.assert_close(tf[:2], torch.tensor([4.0, 2.0]))
    assert float(tf[2] - tn[2]) == 0.0 and float(tf[3] - tn[3]) == 0.0  # misses; box behind the ray


def _field(seed: int = 0, shape=(6, 7, 8), c: int = 3) -> FieldTensors:
    g = torch.Generator().manual_seed(seed)
    grid = torch.randn((1, 1 + c, *shape), generator=g) * 2.0
    occ = torch.rand(shape, generator=g) > 0.4
    return FieldTensors(grid, torch.tensor([-1.0, -1.0, -1.0]), torch.tensor([1.0, 1.0, 1.0]), occ, 0.5, 48, 0.05)


def test_packed_rendering_equals_the_reference_with_empty_samples_at_zero_density():
    f = _field()
    c2w = torch.eye(4)
    c2w[2, 3] = -3.0  # looking down +z at the box from z = −3
    K = torch.tensor([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    g = torch.Generator().manual_seed(5)
    px, py = torch.rand(30, generator=g) * 16, torch.rand(30, generator=g) * 12
    px[0], py[0] = -400.0, -300.0  # a ray that misses the box
    o, d = pixel_rays(c2w, K, px, py)
    bg = torch.tensor([0.2, 0.4, 0.6])
    grid = f.grid.clone().requires_grad_(True)
    f.grid = grid
    rgb, acc = render_rays(f, o, d, bg)
    (rgb.sum() + acc.sum()).backward()
    assert grid.grad is not None
    torch.testing.assert_close(rgb[0], bg)
    # reference: every sample interpolated, unoccupied ones at σ = 0, float64 one-ray compositing
    tn, tf = ray_aabb(o, d, f.lo, f.hi, f.near)
    grid64 = f.grid.detach().double().requires_grad_(True)
    f64 = FieldTensors(grid64, f.lo.double(), f.hi.double(), f.occupancy, f.density_shift, f.n_samples, f.near)
    ref_rgb, ref_acc = [], []
    for i in range(o.shape[0]):
        s = f.n_samples
        t = tn[i].double() + (torch.arange(s, dtype=torch.float64) + 0.5) / s * (tf[i] - tn[i]).double()
        pts = o[i].double() + t[:, None] * d[i].double()
        raw = query(f64, pts)
        keep = occupied(f64, pts) & (tf[i] > tn[i])
        sig = torch.where(keep, torch.nn.functional.softplus(raw[:, 0] + f.density_shift), 0.0)
        delta = ((tf[i] - tn[i]).double() / s).expand(s)
        a, b = composite_ray(sig, torch.sigmoid(raw[:, 1:]), delta, bg.double())
        ref_rgb.append(a)
        ref_acc.append(b)
    rr, ra = torch.stack(ref_rgb), torch.stack(ref_acc)
    torch.testing.assert_close(rgb.double(), rr, rtol=RTOL, atol=1e-5)
    torch.testing.assert_close(acc.double(), ra, rtol=RTOL, atol=1e-5)
    (rr.sum() + ra.sum()).backward()
    assert grid64.grad is not None
    torch.testing.assert_close(grid.grad.double(), grid64.grad, rtol=1e-3, atol=1e-5)
    assert np.count_nonzero(grid.grad.numpy()) > 0


def test_unoccupied_field_and_rays_outside_are_background_with_finite_gradients():
    f = _field(seed=2)
    f.occupancy = torch.zeros_like(f.occupancy)
    f.grid = f.grid.clone().requires_grad_(True)
    o = torch.tensor([[0.0, 0.0, -3.0], [5.0, 5.0, 5.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    bg = torch.tensor([0.1, 0.2, 0.3])
    rgb, acc = render_rays(f, o, d, bg, jitter=torch.rand(2, 1))
    (rgb.sum() + acc.sum()).backward()
    torch.testing.assert_close(rgb, bg.expand(2, 3))
    assert torch.all(acc == 0) and f.grid.grad is not None and torch.all(f.grid.grad == 0)
