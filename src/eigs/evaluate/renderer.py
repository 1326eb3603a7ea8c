"""Render a saved model without the trainer, quantised to 8 bits by the one rule of :func:`eigs.util.image.to_uint8`
(as the PNG writer does): a Gaussian cloud (``model.ply``, the 3DGS parametrisation as tensors, rendered through
:func:`eigs.render.gaussians.render_gaussians`, the function training renders with) or a radiance field
(``model.npz`` of a field run, rendered through :func:`eigs.render.field.render_image`, as training's held-out
log). :func:`load_model` picks by the run folder's model file."""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from eigs.artifacts.field import FIELD_FILE, read_field
from eigs.artifacts.gaussians import GaussianCloud, read_gaussian_ply
from eigs.artifacts.run import MODEL_PLY
from eigs.errors import EigsError
from eigs.render.field import FieldTensors, render_image
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


def load_model(run_dir: Path, sh_degree: int, channels: int, device: torch.device) -> CloudTensors | FieldTensors:
    """The run's model: ``model.npz`` (a field run) when present, else ``model.ply`` at ``sh_degree``."""
    if (run_dir / FIELD_FILE).is_file():
        field = FieldTensors.from_arrays(read_field(run_dir / FIELD_FILE), device)
        if field.channels != channels:
            raise EigsError(run_dir / FIELD_FILE, f"the field has {field.channels} channels, the scene {channels}")
        return field
    ply = run_dir / MODEL_PLY
    if not ply.is_file():
        raise EigsError(run_dir, f"no {MODEL_PLY} or {FIELD_FILE} (not a finished run folder)")
    cloud = read_gaussian_ply(ply)
    if len(cloud) == 0:
        raise EigsError(ply, "the model has no Gaussians")
    cloud.validate(ply)
    return cloud_tensors(cloud, sh_degree, channels, device)


@torch.no_grad()
def render_uint8(
    g: CloudTensors | FieldTensors, c2w: np.ndarray, K: np.ndarray, width: int, height: int, background: np.ndarray
) -> tuple[list[np.ndarray], list[float]]:
    """Render every camera ``c2w`` (M, 4, 4) with intrinsics ``K`` (M, 3, 3); returns the (H, W, C) uint8 images
    and the seconds each render took (synchronised on CUDA; the quantisation and copy to the host not counted).
    One warm-up render precedes the timed ones so a first-use build or allocation is not counted."""
    dev = g.grid.device if isinstance(g, FieldTensors) else g.means.device
    bg = torch.tensor(np.asarray(background, np.float32), device=dev)

    def one(i: int) -> torch.Tensor:
        if isinstance(g, FieldTensors):
            k = torch.from_numpy(np.asarray(K[i], np.float32)).to(dev)
            return render_image(g, torch.from_numpy(np.asarray(c2w[i])), k, width, height, bg)
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
