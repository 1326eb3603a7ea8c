"""Image helpers shared by the stages: the sRGB ↔ linear pair, one float → uint8 rule and one PNG writer.

Rounding rule: clip to [0, 1], then ⌊255·x + 0.5⌋ computed in float64 (round half up), the rule the synthetic
scenes are stored with; NaN becomes 0. Exact for every value that came from uint8 (k/255 ↦ k).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.atomic import FULL_BELOW, atomic_path, disk_full_error, free_bytes


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """sRGB-encoded values (any shape; clipped to [0, 1]) → float64 linear intensity in [0, 1] (IEC 61966-2-1)."""
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    """Inverse of :func:`srgb_to_linear`: linear intensity (any shape; clipped to [0, 1]) → float64 sRGB in
    [0, 1]."""
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)


def to_uint8(image: np.ndarray) -> np.ndarray:
    """Float values in [0, 1] (any shape) → uint8 by the module's rounding rule."""
    x = np.nan_to_num(np.asarray(image, np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.floor(np.clip(x, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W), (H, W, 1), (H, W, 3) RGB or (H, W, 4) RGBA image (float in [0, 1] or uint8) as an 8-bit
    PNG, atomically."""
    import cv2

    a = np.asarray(image)
    a = a if a.dtype == np.uint8 else to_uint8(a)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    elif a.ndim == 3 and a.shape[2] == 3:
        a = np.ascontiguousarray(a[..., ::-1])  # OpenCV writes BGR
    elif a.ndim == 3 and a.shape[2] == 4:
        a = np.ascontiguousarray(a[..., [2, 1, 0, 3]])  # BGRA
    elif a.ndim != 2:
        raise ValueError(f"expected (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got {a.shape}")
    with atomic_path(Path(path)) as tmp:
        if not cv2.imwrite(str(tmp), a):  # OpenCV says no more than False (libpng: "Write Error")
            free = free_bytes(tmp)
            if free is not None and free < FULL_BELOW:
                raise disk_full_error(path, free)
            raise EigsError(path, "could not write the PNG")
