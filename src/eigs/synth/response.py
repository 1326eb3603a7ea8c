"""A built-in scene's frames through its camera response (``linear`` or ``srgb``): linear intensity ↔ uint8."""

from __future__ import annotations

import numpy as np

from eigs.util.image import linear_to_srgb, srgb_to_linear, to_uint8


def encode(linear: np.ndarray, response: str) -> np.ndarray:
    """Linear intensity (any shape, [0, 1]) → uint8: round(255·x) (``linear``) or round(255·sRGB(x)) (``srgb``)."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return to_uint8(linear_to_srgb(x) if response == "srgb" else x)


def decode(u8: np.ndarray, response: str) -> np.ndarray:
    """Inverse of :func:`encode` up to quantisation: uint8 → float64 linear intensity in [0, 1]."""
    x = np.asarray(u8, dtype=np.float64) / 255.0
    return srgb_to_linear(x) if response == "srgb" else x
