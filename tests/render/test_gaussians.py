"""Spherical harmonics and the model renderer (eigs.render.gaussians)."""

from __future__ import annotations

import math

import torch

from eigs.render import rasterize
from eigs.render.gaussians import SH_C0, render_gaussians, sh_basis, sh_to_color


def _sphere(n: int) -> torch.Tensor:
    """n nearly uniform unit vectors (Fibonacci lattice)."""
    i = torch.arange(n, dtype=torch.float64) + 0.5
    phi = torch.acos(1 - 2 * i / n)
    theta = math.pi * (1 + 5**0.5) * i
    return torch.stack([torch.cos(theta) * torch.sin(phi), torch.sin(theta) * torch.sin(phi), torch.cos(phi)], dim=1)


def test_sh_basis_is_orthonormal_on_the_sphere():
    d = _sphere(200_000)
    b = sh_basis(d, 3)  # (n, 16)
    gram = 4 * math.pi * (b.T @ b) / d.shape[0]
    torch.testing.assert_close(gram, torch.eye(16, dtype=torch.float64), atol=2e-4, rtol=0)


def test_degree_one_is_the_linear_band():
    d = _sphere(7)
    b = sh_basis(d, 1)
    c1 = math.sqrt(3 / (4 * math.pi))
    torch.testing.assert_close(b[:, 1:], torch.stack([-c1 * d[:, 1], c1 * d[:, 2], -c1 * d[:, 0]], 1))
    assert abs(SH_C0 - 1 / (2 * math.sqrt(math.pi))) < 1e-15


def test_colour_from_sh_degree_zero_and_view_dependence():
    sh = torch.zeros(2, 4, 3, dtype=torch.float64)
    sh[:, 0] = torch.tensor([[1.0, -1.0, 0.0], [0.2, 0.4, -10.0]], dtype=torch.float64)
    means = torch.tensor([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], dtype=torch.float64)
    c = sh_to_color(sh, means, torch.zeros(3, dtype=torch.float64), 0)
    torch.testing.assert_close(c, (0.5 + SH_C0 * sh[:, 0]).clamp_min(0))
    sh[0, 3, 0] = 1.0  # the −x lobe: seen along +x, red goes down
    c1 = sh_to_color(sh, means, torch.zeros(3, dtype=torch.float64), 1)
    torch.testing.assert_close(c1[1, 0], torch.tensor(0.5 + SH_C0 * 0.2, dtype=torch.float64))  # no rest on #1
    assert c1[0, 0] == 0.5 + SH_C0 * 1.0  # d = +z: the x lobe is zero


def test_render_gaussians_equals_rasterize_with_activations():
    g = torch.Generator().manual_seed(0)
    n = 40
    means = torch.randn(n, 3, generator=g) * 0.3 + torch.tensor([0, 0, 3.0])
    quats = torch.randn(n, 4, generator=g)
    log_scales = torch.randn(n, 3, generator=g) * 0.2 - 2.5
    opac = torch.randn(n, generator=g)
    sh = torch.randn(n, 1, 3, generator=g)
    c2w = torch.eye(4, dtype=torch.float64)
    c2w[:3, 3] = torch.tensor([0.1, -0.2, 0.3], dtype=torch.float64)
    K = torch.tensor([[40.0, 0, 16], [0, 40.0, 12], [0, 0, 1]])
    img, alpha, _ = render_gaussians(means, quats, log_scales, opac, sh, c2w, K, 32, 24, sh_degree=0)
    ref, ref_a, _ = rasterize(means, quats, log_scales.exp(), opac.sigmoid(), (0.5 + SH_C0 * sh[:, 0]).clamp_min(0),
                              torch.linalg.inv(c2w).float(), K, 32, 24)  # fmt: skip
    torch.testing.assert_close(img, ref)
    torch.testing.assert_close(alpha, ref_a)
