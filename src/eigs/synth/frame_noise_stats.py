"""APS frame noise measured on a real recording: temporal noise, its photon transfer, fixed-pattern upper bounds.

For a few consecutive 8-bit frames ``(V, H, W)`` of a still-ish scene and the events around them (the DAVIS346
recording ``../shared/data/real/davis346_lab``: 3 frames, 4.8 ms exposures; ``bench/aps_noise.py`` reads it through
``eigs.ingest.aedat4``), in DN (1/255 of full scale):

- **still, flat pixels** of a frame pair (k, k + 1): no event in the pixel's 5 × 5 neighbourhood from the start of
  exposure k to the end of exposure k + 1, Sobel gradient of the frames' mean below 1 DN/px (the Sobel sum / 8),
  mean level in (2, 250) DN (no clipping);
- **temporal noise** σ_t: ``sqrt(var(f[k+1] − f[k]) / 2)`` over those pixels of every pair (a still pixel's two
  frames differ only by temporal noise), with its 95 % chi-square interval;
- **photon transfer**: the same variance in 10-DN bins of the mean level (≥ 300 pixels a bin), fitted by weighted
  least squares ``var = a + b · level``: ``b`` DN²/DN is the inverse conversion gain (``1 / b`` e⁻/DN), ``255 / b``
  the electrons at full scale, ``sqrt(a − 1/12)`` the read noise without the 8-bit quantisation's 1/12 DN²;
- **pixel FPN, upper bound**: the frames' mean minus its 5 × 5 median at pixels still and flat in every pair, its
  standard deviation with the temporal part (σ_t²/V) removed: scene texture left by the flatness test adds to it;
- **column FPN**: per column, the mean over its still flat pixels (≥ 30) of the frames' mean minus its 9-column
  running mean (× sqrt(9/8), the variance that high-pass removes from independent offsets); their standard deviation
  over columns. The same over rows is the control: the DAVIS readout is column-parallel, so rows carry no offset of
  their own and their figure is what scene and temporal noise leave; ``column_fpn_excess_dn`` = sqrt(col² − row²).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import ndimage as ndi
from scipy.stats import chi2

QUANTISATION_VAR = 1.0 / 12.0  # DN², uniform rounding to 8 bits
BIN_DN = 10.0
MIN_BIN = 300
MIN_LINE = 30


def _gradient(mean: np.ndarray) -> np.ndarray:
    return np.hypot(ndi.sobel(mean, 0), ndi.sobel(mean, 1)) / 8.0


def still_masks(frames: np.ndarray, exposure_us: np.ndarray, x: np.ndarray, y: np.ndarray,
                t: np.ndarray) -> list[np.ndarray]:  # fmt: skip
    """``(H, W)`` bool per consecutive frame pair: still (no event nearby), flat and unclipped (module docstring)."""
    v, h, w = frames.shape
    mean = frames.astype(np.float64).mean(axis=0)
    flat = (_gradient(mean) < 1.0) & (mean > 2) & (mean < 250)
    out = []
    for k in range(v - 1):
        sel = (t >= exposure_us[k, 0]) & (t < exposure_us[k + 1, 1])
        count = np.zeros((h, w))
        np.add.at(count, (y[sel].astype(np.int64), x[sel].astype(np.int64)), 1)
        out.append(flat & (ndi.maximum_filter(count, 5) == 0))
    return out


def _line_fpn(hp: np.ndarray, mask: np.ndarray, axis: int) -> tuple[float, int]:
    """Std over lines (columns for ``axis`` 0, rows for 1) of the mean of ``hp`` over each line's masked pixels."""
    n = mask.sum(axis=axis)
    means = (hp * mask).sum(axis=axis) / np.maximum(n, 1)
    ok = n >= MIN_LINE
    return float(means[ok].std(ddof=1)), int(ok.sum())


def measure(frames: np.ndarray, exposure_us: np.ndarray, x: np.ndarray, y: np.ndarray, t: np.ndarray) -> dict[str, Any]:
    """The module docstring's figures from ``frames`` ``(V, H, W)`` uint8 (V ≥ 2) with exposures ``(V, 2)`` µs and
    the events ``x``, ``y``, ``t`` (µs, the same clock). Values in DN of the 8-bit frames."""
    f = frames.astype(np.float64)
    v = f.shape[0]
    masks = still_masks(frames, exposure_us, x, y, t)
    mean = f.mean(axis=0)
    diffs = np.concatenate([(f[k + 1] - f[k])[m] for k, m in enumerate(masks)])
    levels = np.concatenate([mean[m] for m in masks])
    n = diffs.size
    var_t = float(diffs.var(ddof=1)) / 2
    lo, hi = chi2.interval(0.95, n - 1)
    bins = []
    for a in np.arange(0.0, 250.0, BIN_DN):
        sel = (levels >= a) & (levels < a + BIN_DN)
        if sel.sum() >= MIN_BIN:
            bins.append((float(levels[sel].mean()), float(diffs[sel].var(ddof=1)) / 2, int(sel.sum())))
    lv, vr, cnt = (np.array(c) for c in zip(*bins, strict=True))
    (b, a), *_ = np.linalg.lstsq(np.stack([lv, np.ones_like(lv)], 1) * np.sqrt(cnt)[:, None], vr * np.sqrt(cnt),
                                 rcond=None)  # fmt: skip
    every = np.logical_and.reduce(masks)
    resid = (mean - ndi.median_filter(mean, 5))[every]
    pixel = float(np.sqrt(max(resid.var(ddof=1) - var_t / v, 0.0)))
    col, n_col = _line_fpn((mean - ndi.uniform_filter1d(mean, 9, axis=1)) * np.sqrt(9 / 8), every, 0)
    row, n_row = _line_fpn((mean - ndi.uniform_filter1d(mean, 9, axis=0)) * np.sqrt(9 / 8), every, 1)
    return {
        "frames": int(v),
        "exposure_us": [int(e) for e in np.diff(exposure_us, axis=1)[:, 0]],
        "still_pixels": int(n),
        "mean_level_dn": float(levels.mean()),
        "temporal_std_dn": float(np.sqrt(var_t)),
        "temporal_std_ci95_dn": [float(np.sqrt(var_t * (n - 1) / hi)), float(np.sqrt(var_t * (n - 1) / lo))],
        "ptc_bins": [{"level_dn": round(l_, 2), "var_dn2": round(v_, 4), "n": c_} for l_, v_, c_ in bins],
        "ptc_slope_dn": float(b),
        "ptc_intercept_dn2": float(a),
        "gain_e_per_dn": float(1.0 / b) if b > 0 else None,
        "full_well_e": float(255.0 / b) if b > 0 else None,
        "read_noise_dn": float(np.sqrt(max(a - QUANTISATION_VAR, 0.0))),
        "pixel_fpn_upper_dn": pixel,
        "pixels_still_in_every_pair": int(every.sum()),
        "column_fpn_dn": col,
        "columns": n_col,
        "row_control_dn": row,
        "rows": n_row,
        "column_fpn_excess_dn": float(np.sqrt(max(col**2 - row**2, 0.0))),
    }
