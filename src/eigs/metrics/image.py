"""Input handling shared by the metrics: reading files, dtypes, channels, size checks.

Conventions (one place decides them):

- An image is a NumPy array ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` (RGB) or ``(H, W, 4)`` (RGBA), either
  uint8 in [0, 255], uint16 in [0, 65535], or float in [0, 1]. Floats outside [0, 1] (beyond 1e-6) are refused,
  never clipped silently; non-finite values are refused.
- Alpha is dropped (the RGB values are compared as stored, not composited).
- A 1-channel image is compared with an RGB one by repeating its channel; LPIPS always repeats it to RGB.
- Files are read with OpenCV: 8-bit as is, 16-bit rounded to 8 bits (``round(v / 257)``), because metrics are
  defined here on 8-bit images as a user saves them.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.image import to_uint8 as util_to_uint8

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".ppm", ".pgm")


def _as_hwc(img: np.ndarray, name: str) -> np.ndarray:
    """``(H, W, C)`` view of ``img`` with C in {1, 3}; alpha dropped. Raises for other shapes."""
    arr = np.asarray(img)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or arr.shape[2] not in (1, 3, 4):
        raise EigsError(name, f"expected an (H, W), (H, W, 1), (H, W, 3) or (H, W, 4) image, got shape {arr.shape}")
    if arr.shape[0] == 0 or arr.shape[1] == 0:
        raise EigsError(name, f"empty image of shape {arr.shape}")
    if arr.shape[2] == 4:
        arr = arr[:, :, :3]
    return arr


def to_float(img: np.ndarray, name: str = "image") -> np.ndarray:
    """``(H, W, C)`` float64 in [0, 1], C in {1, 3}, from uint8/uint16/bool/float input (see module doc)."""
    arr = _as_hwc(img, name)
    if arr.dtype == np.uint8:
        return arr.astype(np.float64) / 255.0
    if arr.dtype == np.uint16:
        return arr.astype(np.float64) / 65535.0
    if arr.dtype == np.bool_:
        return arr.astype(np.float64)
    if not np.issubdtype(arr.dtype, np.floating):
        raise EigsError(name, f"unsupported dtype {arr.dtype}; expected uint8, uint16 or float in [0, 1]")
    out = arr.astype(np.float64)
    if not np.all(np.isfinite(out)):
        raise EigsError(name, "image has NaN or infinite values")
    lo, hi = float(out.min()), float(out.max())
    if lo < -1e-6 or hi > 1 + 1e-6:
        raise EigsError(name, f"float image values span [{lo:.4g}, {hi:.4g}]; expected [0, 1]")
    return np.clip(out, 0.0, 1.0)


def to_uint8(img: np.ndarray, name: str = "image") -> np.ndarray:
    """``(H, W, C)`` uint8, C in {1, 3}: uint8 as is, others via :func:`to_float` and the one rounding rule of
    :func:`eigs.util.image.to_uint8` (⌊255 v + 0.5⌋)."""
    arr = _as_hwc(img, name)
    if arr.dtype == np.uint8:
        return np.ascontiguousarray(arr)
    return util_to_uint8(to_float(arr, name))


def match_channels(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Repeat a 1-channel ``(H, W, 1)`` image to 3 channels when the other has 3."""
    if a.shape[2] == 1 and b.shape[2] == 3:
        a = np.repeat(a, 3, axis=2)
    elif b.shape[2] == 1 and a.shape[2] == 3:
        b = np.repeat(b, 3, axis=2)
    return a, b


def float_pair(img: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both images as ``(H, W, C)`` float64 in [0, 1] with equal shapes; :class:`EigsError` if sizes differ."""
    a, b = to_float(img, "image"), to_float(ref, "reference")
    check_same_size(a, b)
    return match_channels(a, b)


def check_same_size(a: np.ndarray, b: np.ndarray) -> None:
    """Raise :class:`EigsError` unless ``a`` and ``b`` have the same height and width."""
    if a.shape[:2] != b.shape[:2]:
        raise EigsError(
            None,
            f"image is {a.shape[1]}x{a.shape[0]} (WxH) but reference is {b.shape[1]}x{b.shape[0]}; sizes must match",
        )


def read_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file as ``(H, W, C)`` uint8, C in {1, 3} (RGB order; alpha dropped; 16 bits -> 8 bits)."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise EigsError(path, "no such image file")
    data = np.fromfile(path, dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if img is None:
        raise EigsError(path, "cannot decode this file as an image")
    if img.dtype == np.uint16:
        img = util_to_uint8(img.astype(np.float64) / 65535.0)  # = round(v / 257): never a tie for integers
    elif img.dtype != np.uint8:
        raise EigsError(path, f"unsupported pixel type {img.dtype}; save the image with 8 bits per channel")
    if img.ndim == 2:
        return img[:, :, None]
    if img.shape[2] == 4:
        img = img[:, :, :3]
    if img.shape[2] == 3:
        return np.ascontiguousarray(img[:, :, ::-1])
    if img.shape[2] == 1:
        return img
    raise EigsError(path, f"unsupported channel count {img.shape[2]}")
