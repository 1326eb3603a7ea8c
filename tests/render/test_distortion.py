"""Mip-NeRF 360's distortion loss (eigs.render.volume.distortion) against its O(S²) definition in float64, forward
and backward, and its closed form for a single opaque interval."""

from __future__ import annotations

import torch

from eigs.render.volume import distortion


def _brute(w: torch.Tensor, s: torch.Tensor, ds: torch.Tensor) -> torch.Tensor:
    out = []
    for r in range(w.shape[0]):
        total = (w[r, :, None] * w[r, None, :] * (s[r, :, None] - s[r, None, :]).abs()).sum()
        out.append(total + (w[r] ** 2 * ds[r]).sum() / 3.0)
    return torch.stack(out)


def test_distortion_matches_the_quadratic_definition_forward_and_backward():
    g = torch.Generator().manual_seed(0)
    r, n = 7, 30
    w = torch.rand((r, n), generator=g, dtype=torch.float64) / n
    w[0] = 0.0  # an empty ray
    w[1, 10:] = 0.0  # padding after the last sample
    s = torch.sort(torch.rand((r, n), generator=g, dtype=torch.float64), dim=1).values
    ds = torch.rand((r, n), generator=g, dtype=torch.float64) * 0.05
    a = w.clone().requires_grad_(True)
    b = w.clone().requires_grad_(True)
    got, ref = distortion(a, s, ds), _brute(b, s, ds)
    torch.testing.assert_close(got, ref, rtol=1e-12, atol=1e-15)
    assert got[0].item() == 0.0
    probe = torch.rand(r, generator=g, dtype=torch.float64)
    (got * probe).sum().backward()
    (ref * probe).sum().backward()
    torch.testing.assert_close(a.grad, b.grad, rtol=1e-12, atol=1e-15)
    # float32 against the float64 definition
    torch.testing.assert_close(distortion(w.float(), s.float(), ds.float()).double(), ref.detach(), rtol=1e-5,
                               atol=1e-7)  # fmt: skip


def test_distortion_prefers_one_surface_to_spread_weight():
    s = torch.linspace(0.005, 0.995, 100, dtype=torch.float64)[None]
    ds = torch.full_like(s, 0.01)
    one = torch.zeros_like(s)
    one[0, 40] = 1.0  # all the weight in one interval: ⅓ · 1² · Δs
    torch.testing.assert_close(distortion(one, s, ds), torch.tensor([0.01 / 3], dtype=torch.float64))
    spread = torch.full_like(s, 0.01)  # the same total weight spread along the ray
    assert float(distortion(spread, s, ds)) > 50 * float(distortion(one, s, ds))
