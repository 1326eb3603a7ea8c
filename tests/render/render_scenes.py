"""Random scenes and comparison helpers shared by the rasterizer tests."""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from eigs.render.reference import render_reference


@dataclass
class Scene:
    means: Tensor
    quats: Tensor
    scales: Tensor
    opacities: Tensor
    colors: Tensor
    viewmat: Tensor
    K: Tensor
    width: int
    height: int
    background: Tensor

    def args(self) -> tuple:
        return (self.means, self.quats, self.scales, self.opacities, self.colors, self.viewmat, self.K,
                self.width, self.height, self.background)  # fmt: skip

    def to(self, dtype: torch.dtype, grad: bool = False) -> Scene:
        def c(t: Tensor) -> Tensor:
            return t.detach().to(dtype).clone().requires_grad_(grad)

        return Scene(c(self.means), c(self.quats), c(self.scales), c(self.opacities), c(self.colors),
                     self.viewmat.to(dtype), self.K.to(dtype), self.width, self.height,
                     c(self.background))  # fmt: skip

    def leaves(self) -> list[Tensor]:
        return [self.means, self.quats, self.scales, self.opacities, self.colors, self.background]


LEAF_NAMES = ["means", "quats", "scales", "opacities", "colors", "background"]


def random_scene(
    n: int,
    width: int,
    height: int,
    d: int = 3,
    seed: int = 0,
    opacity: tuple[float, float] = (0.02, 0.99),
    log_scale: tuple[float, float] = (-4.0, -2.0),
    margin: float = 12.0,
    dtype: torch.dtype = torch.float32,
) -> Scene:
    """N Gaussians whose centres project uniformly over the image plus ``margin`` px on every side (so many
    straddle tile and image borders), depths 2..6, anisotropic scales, a rotated and translated camera and an
    off-centre principal point."""
    g = torch.Generator().manual_seed(seed)

    def u(*shape: int) -> Tensor:
        return torch.rand(*shape, generator=g, dtype=torch.float64)

    fx, fy = 0.8 * width + 7.0, 0.8 * width - 3.0
    cx, cy = 0.43 * width, 0.58 * height
    K = torch.tensor([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]], dtype=torch.float64)
    px = -margin + (width + 2 * margin) * u(n)
    py = -margin + (height + 2 * margin) * u(n)
    z = 2.0 + 4.0 * u(n)
    cam = torch.stack([(px - cx) * z / fx, (py - cy) * z / fy, z], -1)
    # camera: a rotation about a tilted axis and a translation; means = R^T (cam - t)
    ang = 0.3
    axis = torch.tensor([0.3, -0.5, 0.8], dtype=torch.float64)
    axis = axis / axis.norm()
    kx = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    sin, cos = torch.sin(torch.tensor(ang)), torch.cos(torch.tensor(ang))
    R = torch.eye(3, dtype=torch.float64) + sin * kx + (1 - cos) * kx @ kx
    t = torch.tensor([0.2, -0.1, 0.3], dtype=torch.float64)
    viewmat = torch.eye(4, dtype=torch.float64)
    viewmat[:3, :3], viewmat[:3, 3] = R, t
    means = (cam - t) @ R
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    scales = torch.exp(log_scale[0] + (log_scale[1] - log_scale[0]) * u(n, 3)) * z[:, None] / 4
    opac = opacity[0] + (opacity[1] - opacity[0]) * u(n)
    colors = u(n, d)
    bg = u(d)
    return Scene(means, quats, scales, opac, colors, viewmat, K, width, height, bg).to(dtype)


def rel_l2(x: Tensor, y: Tensor) -> float:
    """||x - y|| / ||y|| (0 when both vanish)."""
    x, y = x.double(), y.double()
    den = float(y.norm())
    num = float((x - y).norm())
    return num / den if den > 0 else num


def reference(scene: Scene) -> tuple[Tensor, Tensor, dict]:
    """The dense reference in float64 of ``scene`` (detached copies)."""
    return render_reference(*scene.to(torch.float64).args())
