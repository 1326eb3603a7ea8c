"""Image helpers shared by the stages: one float → uint8 rule and one PNG writer.

Rounding rule: clip to [0, 1], then ⌊255·x + 0.5⌋ (round half up), the rule the synthetic scenes are stored with;
NaN becomes 0. Exact for every value that came from uint8 (k/255 ↦ k).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.atomic import atomic_path


def to_uint8(image: np.ndarray) -> np.ndarray:
    """Float values in [0, 1] (any shape) → uint8 by the module's rounding rule."""
    x = np.nan_to_num(np.asarray(image, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.floor(np.clip(x, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W), (H, W, 1) or (H, W, 3) RGB image (float in [0, 1] or uint8) as an 8-bit PNG, atomically."""
    import cv2

    a = np.asarray(image)
    a = a if a.dtype == np.uint8 else to_uint8(a)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    elif a.ndim == 3 and a.shape[2] == 3:
        a = np.ascontiguousarray(a[..., ::-1])  # OpenCV writes BGR
    elif a.ndim != 2:
        raise ValueError(f"expected (H, W), (H, W, 1) or (H, W, 3), got {a.shape}")
    with atomic_path(Path(path)) as tmp:
        if not cv2.imwrite(str(tmp), a):
            raise EigsError(path, "could not write the PNG")
