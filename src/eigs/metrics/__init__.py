"""Image-quality metrics: PSNR, SSIM (three lineages), LPIPS (AlexNet/VGG, offline), sharpness (the high-frequency
power ratio), coherence (the reference's high-frequency detail reproduced) and BRISQUE (offline).

Every metric takes images as ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` arrays, uint8 in [0, 255]
or float in [0, 1] (see :mod:`eigs.metrics.image`). LPIPS and BRISQUE need model files prepared once with
``eigs resources`` (see :mod:`eigs.metrics.resources`). ``docs/metrics.md`` gives the definitions.

The submodules import numpy/torch; this package itself stays light so ``eigs --help`` is fast. The public
functions are importable from here lazily:
``from eigs.metrics import psnr, ssim, lpips, hf_ratio, hf_coherence, brisque``.
"""

from __future__ import annotations

import importlib
from typing import Any

# Submodule names differ from the function names on purpose: importing ``eigs.metrics.ssim`` as a module
# would otherwise shadow the function ``ssim`` on this package.
_LAZY = {
    "psnr": "eigs.metrics.pixel",
    "ssim": "eigs.metrics.pixel",
    "ssim_torch": "eigs.metrics.pixel",
    "SSIM_MODES": "eigs.metrics.pixel",
    "lpips": "eigs.metrics.perceptual",
    "LPIPS": "eigs.metrics.perceptual",
    "brisque": "eigs.metrics.noreference",
    "hf_ratio": "eigs.metrics.sharpness",
    "hf_coherence": "eigs.metrics.sharpness",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'eigs.metrics' has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
