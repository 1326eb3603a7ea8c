"""Latent timestamps and event binning (vectorised; no Python loop over events).

Conventions: time in int64 µs, polarity ±1, pixel (x, y) = (column, row). A view's exposure is the half-open
interval [start, end). Latent frames k = 0..B sit at times t_0 < … < t_B inside it; bin k (k = 0..B−1) holds the
signed net event count over the half-open interval [t_k, t_{k+1}).
"""

from __future__ import annotations

import numpy as np

from eigs.errors import EigsError

MIN_BINS, MAX_BINS = 1, 64


def latent_times(exposure_us: np.ndarray, bins: int) -> np.ndarray:
    """Latent timestamps spread over each exposure, from its start to its end:

        t_k = start + ⌊k · (end − start) / B⌋,   k = 0..B.

    This is the synthetic generator's convention (its ``poses/latent_t_us`` at B = 4 equal this exactly) and close to
    E²NeRF's (latent poses at sub-frames 1, 5, 9, 13, 17 of 18). The B bins [t_k, t_{k+1}) then cover the whole
    exposure [start, end), so every exposure event is binned.

    ``exposure_us``: (V, 2) int64 [start, end). Returns (V, B + 1) int64, non-decreasing per view.
    """
    exposure_us = np.asarray(exposure_us, dtype=np.int64).reshape(-1, 2)
    k = np.arange(bins + 1, dtype=np.int64)
    dur = exposure_us[:, 1] - exposure_us[:, 0]
    return exposure_us[:, :1] + (k[None, :] * dur[:, None]) // bins


def bin_events(
    x: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    p: np.ndarray,
    edges_us: np.ndarray,
    height: int,
    width: int,
    mask: np.ndarray | None = None,
) -> np.ndarray:
    """Signed event counts per bin between consecutive edges.

    ``x``, ``y``: (N,) integer pixel coordinates; ``t``: (N,) int64 µs, need not be sorted; ``p``: (N,) ±1;
    ``edges_us``: (B + 1,) int64 strictly increasing; event i goes to bin k when edges[k] ≤ t_i < edges[k+1],
    events outside [edges[0], edges[B]) are ignored. ``mask``: optional (H, W) bool, True = ignore the pixel's
    events (hot/flickering pixels). Returns (B, H, W) int32.
    """
    on, off = polarity_counts(x, y, t, p, edges_us, height, width, mask)
    return (on - off).astype(np.int32)


def polarity_counts(
    x: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    p: np.ndarray,
    edges_us: np.ndarray,
    height: int,
    width: int,
    mask: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(ON, OFF) event counts per bin, both ≥ 0, each (B, H, W) int64; arguments as :func:`bin_events` (whose
    signed counts are ON − OFF). Integer bincounts keep the sums exact."""
    edges_us = np.asarray(edges_us, dtype=np.int64)
    nb = edges_us.shape[0] - 1
    if nb < 1 or np.any(np.diff(edges_us) <= 0):
        raise ValueError(f"edges must be strictly increasing with at least 2 entries, got {edges_us.tolist()}")
    t = np.asarray(t, dtype=np.int64)
    k = np.searchsorted(edges_us, t, side="right") - 1
    keep = (k >= 0) & (k < nb)
    pix = np.asarray(y, dtype=np.int64) * width + np.asarray(x, dtype=np.int64)
    if mask is not None:
        keep &= ~np.asarray(mask, dtype=bool).reshape(-1)[pix]
    idx = k[keep] * (height * width) + pix[keep]
    pol = np.asarray(p)[keep]
    n = nb * height * width
    on = np.bincount(idx[pol > 0], minlength=n).reshape(nb, height, width)
    off = np.bincount(idx[pol < 0], minlength=n).reshape(nb, height, width)
    return on.astype(np.int64), off.astype(np.int64)


def cumulative_counts(counts: np.ndarray) -> np.ndarray:
    """(V, B, H, W) or (B, H, W) bin counts → (V, B + 1, H, W) / (B + 1, H, W) int32 cumulative counts
    S_k = Σ_{i<k} bin_i (S_0 = 0): the signed event integral from latent time 0 to latent time k."""
    counts = np.asarray(counts)
    ax = counts.ndim - 3
    zero = np.zeros_like(counts.take([0], axis=ax), dtype=np.int64)
    cum = np.concatenate([zero, np.cumsum(counts, axis=ax, dtype=np.int64)], axis=ax)
    return np.clip(cum, np.iinfo(np.int32).min, np.iinfo(np.int32).max).astype(np.int32)


def check_prebinned(path: str, n_bins_scene: int, bins: int | None) -> int:
    """The number of bins to use for a pre-binned scene: ``bins`` must match the scene's (or be None)."""
    if bins is not None and bins != n_bins_scene:
        raise EigsError(
            path,
            f"the scene's events are pre-binned into {n_bins_scene} bins (no raw timestamps), so --bins {bins} "
            f"cannot be honoured; use --bins {n_bins_scene}, or ingest the raw events to re-bin",
        )
    return n_bins_scene


def check_bins(bins: int) -> int:
    if not MIN_BINS <= bins <= MAX_BINS:
        raise EigsError(None, f"--bins must be between {MIN_BINS} and {MAX_BINS}, got {bins}")
    return bins
