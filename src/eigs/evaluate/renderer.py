"""Render a saved Gaussian cloud (``model.ply``) without the trainer: the cloud's 3DGS parametrisation as tensors,
rendered through :func:`eigs.render.gaussians.render_gaussians` (the function training renders with), quantised to
8 bits by the one rule of :func:`eigs.util.image.to_uint8` (as the PNG writer does)."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import torch

from eigs.artifacts.gaussians import GaussianCloud
from eigs.render.gaussians import render_gaussians
from eigs.util.image import to_uint8


@dataclass
class CloudTensors:
    """Gaussians ready to render: ``means`` (N, 3), ``quats`` (N, 4), ``log_scales`` (N, 3), ``opacity_logits``
    (N,), ``sh`` (N, (d+1)², C) with C the scene's channels; ``sh_degree`` d."""

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor
    sh_degree: int

    def __len__(self) -> int:
        return int(self.means.shape[0])


def cloud_tensors(cloud: GaussianCloud, sh_degree: int, channels: int, device: torch.device) -> CloudTensors:
    """The cloud at SH degree ``sh_degree`` with ``channels`` colour channels (1: the mean of the PLY's three, as
    training stores grey models three times); higher SH bands the cloud lacks are zero, extra ones dropped."""
    sh = cloud.sh_coefficients(sh_degree, channels)

    def t(a: np.ndarray) -> torch.Tensor:
        return torch.tensor(np.ascontiguousarray(a), dtype=torch.float32, device=device)

    return CloudTensors(t(cloud.means), t(cloud.quats), t(cloud.log_scales), t(cloud.opacity), t(sh), sh_degree)


@torch.no_grad()
def render_uint8(
    g: CloudTensors, c2w: np.ndarray, K: np.ndarray, width: int, height: int, background: np.ndarray
) -> tuple[list[np.ndarray], list[float]]:
    """Render every camera ``c2w`` (M, 4, 4) with intrinsics ``K`` (M, 3, 3); returns the (H, W, C) uint8 images
    and the seconds each render took (synchronised on CUDA; the quantisation and copy to the host not counted).
    One warm-up render precedes the timed ones so a first-use build or allocation is not counted."""
    dev = g.means.device
    bg = torch.tensor(np.asarray(background, np.float32), device=dev)

    def one(i: int) -> torch.Tensor:
        img, _, _ = render_gaussians(
            g.means, g.quats, g.log_scales, g.opacity_logits, g.sh, torch.from_numpy(np.asarray(c2w[i])),
            torch.from_numpy(np.asarray(K[i], np.float32)).to(dev), width, height, background=bg,
            sh_degree=g.sh_degree,
        )  # fmt: skip
        return img

    if len(c2w):
        one(0)
    images, times = [], []
    for i in range(len(c2w)):
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)
        t0 = time.perf_counter()
        img = one(i)
        if dev.type == "cuda":
            torch.cuda.synchronize(dev)
        times.append(time.perf_counter() - t0)
        arr = img.float().cpu().numpy()
        if not np.all(np.isfinite(arr)):
            from eigs.errors import EigsError

            raise EigsError(None, f"render {i} has NaN/Inf pixels (a broken model)")
        images.append(to_uint8(arr))
    return images, times
