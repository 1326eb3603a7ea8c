"""Hot-pixel and flicker mask: pixels whose event rate is far above the scene's.

A pixel is masked when its event count over the whole recording is both in the top ``top_fraction`` of all pixels
(default :attr:`EdiOptions.mask_top`, 1 %) **and** more than ``factor`` times the mean count per pixel (default 8).
The first condition is the usual "top 1 %" rule; the second keeps the mask empty on clean recordings, where the
busiest pixels are ordinary edges a few times busier than average (on the synthetic scenes the busiest pixel has ≈
6× the mean), while hot pixels and lamp flicker run one to two orders of magnitude above it. Masked pixels
contribute no events to binning, the double integral or the threshold energy (their latent frames equal the
blurry frame there).
"""

from __future__ import annotations

import numpy as np

from eigs.edi.options import EdiOptions

TOP_FRACTION = EdiOptions.mask_top  # the defaults live in EdiOptions
FACTOR = EdiOptions.mask_factor


def event_rate_map(x: np.ndarray, y: np.ndarray, height: int, width: int) -> np.ndarray:
    """(H, W) int64 number of events per pixel (both polarities)."""
    pix = np.asarray(y, dtype=np.int64) * width + np.asarray(x, dtype=np.int64)
    return np.bincount(pix, minlength=height * width).reshape(height, width)


def hot_pixel_mask(
    counts: np.ndarray, top_fraction: float = TOP_FRACTION, factor: float = FACTOR
) -> np.ndarray:
    """(H, W) bool, True = masked. ``counts``: (H, W) events per pixel (:func:`event_rate_map`).
    ``top_fraction`` = 0 disables the mask."""
    counts = np.asarray(counts)
    if top_fraction <= 0 or counts.size == 0 or counts.max() == 0:
        return np.zeros(counts.shape, dtype=bool)
    q = float(np.quantile(counts, 1.0 - top_fraction))
    return (counts > q) & (counts > factor * float(counts.mean()))
