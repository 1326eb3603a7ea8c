"""Event losses: EiGS's event-integration loss (paper Eq. 9–10) and the E²NeRF/E2GS pairwise variant.

The intensity model is the one the EDI stage used for the run's artifact: log intensity ``ln(Y + ε)`` of the luma
``Y`` (BT.601) of linear intensity (estimated mode; sRGB frames are linearised first), or of the pixel values as
they are (E²NeRF mode, whose EDI scales 0–255 values: the ×255 cancels in log differences). One event stands for a
log change of C (per view, or per pixel and polarity when EDI calibrated ON/OFF maps).
"""

from __future__ import annotations

import torch
from torch import Tensor

LUMA_WEIGHTS = (0.299, 0.587, 0.114)  # BT.601, as EDI's luma
LOG_EPS = 1e-3  # ε of ln(Y + ε), as EDI (eigs.edi.edi.LOG_EPS; a test checks they agree)


def srgb_to_linear(v: Tensor) -> Tensor:
    """sRGB-encoded [0, 1] → linear [0, 1] (IEC 61966-2-1); inputs clamped to [0, 1] first."""
    v = v.clamp(0.0, 1.0)
    return torch.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055).clamp_min(1e-12) ** 2.4)


def linear_to_srgb(v: Tensor) -> Tensor:
    """Linear [0, 1] → sRGB-encoded [0, 1]; inputs clamped to [0, 1] first."""
    v = v.clamp(0.0, 1.0)
    return torch.where(v <= 0.0031308, v * 12.92, 1.055 * v.clamp_min(1e-12) ** (1 / 2.4) - 0.055)


def to_linear(image: Tensor, response: str) -> Tensor:
    """Pixel values in [0, 1] → linear intensity (``srgb`` decoded; ``linear``/``unknown`` as they are)."""
    return srgb_to_linear(image) if response == "srgb" else image


def from_linear(image: Tensor, response: str) -> Tensor:
    return linear_to_srgb(image) if response == "srgb" else image


def luma(image: Tensor) -> Tensor:
    """(…, H, W, C) → (…, H, W): BT.601 luma for C = 3, the channel for C = 1."""
    if image.shape[-1] == 1:
        return image[..., 0]
    w = torch.tensor(LUMA_WEIGHTS, dtype=image.dtype, device=image.device)
    return image @ w


def log_intensity(image: Tensor, response: str, mode: str = "estimated", eps: float = LOG_EPS) -> Tensor:
    """(…, H, W, C) rendered pixel values → (…, H, W) log intensity of the event model of ``mode``."""
    y = luma(to_linear(image, response) if mode == "estimated" else image)
    return torch.log(y.clamp_min(0.0) + eps)


def event_integration_loss(
    log_a: Tensor,
    log_b: Tensor,
    counts: Tensor,
    c_pos: Tensor | float,
    c_neg: Tensor | float,
    mask: Tensor | None = None,
    deadzone: float = 0.0,
    mismatch: float = 0.0,
) -> Tensor:
    """Eq. 9–10: L1 between the predicted event integral Ẽ = (log_b − log_a)/C and the net event count E of the
    same interval, averaged over the pixels that are not masked.

    ``log_a``, ``log_b``: (H, W) log intensities at the interval's start and end; ``counts``: (H, W) net signed
    counts; ``c_pos``/``c_neg``: thresholds (scalars or (H, W) maps) for rising/falling intensity; ``mask``:
    (H, W) bool, True where events were ignored. Zero exactly when ``log_b − log_a = C·E`` everywhere. A stack of
    K intervals ((K, H, W) logs and counts; thresholds and mask per pixel, shared) gives the mean of the K
    intervals' losses.

    Sensor-noise-aware variant (beyond the paper; both 0 by default, the paper's loss): an error up to
    ``deadzone + mismatch·|E|`` events costs nothing, the excess is L1. ``deadzone`` (events) covers the count's
    quantisation (the sub-threshold residues at both ends of the interval: |Ẽ − E| < 1 for an ideal sensor);
    ``mismatch`` (a fraction) the per-pixel threshold spread σ_C/C that one threshold per view cannot represent and
    the events a refractory period swallows, both growing with the count.
    """
    diff = log_b - log_a
    c = torch.where(diff >= 0, torch.as_tensor(c_pos, dtype=diff.dtype), torch.as_tensor(c_neg, dtype=diff.dtype))
    e = counts.to(diff.dtype)
    err = (diff / c - e).abs()
    if deadzone > 0 or mismatch > 0:
        err = torch.relu(err - (deadzone + mismatch * e.abs()))
    if mask is not None:
        keep = ~mask
        n = keep.sum() * (err.numel() // max(keep.numel(), 1))  # every interval of a stack has the same pixels
        return (err * keep).sum() / n.clamp_min(1)
    return err.mean()


def lin_log(x255: Tensor, knee: float = 20.0) -> Tensor:
    """v2e's lin-log of 0–255 values: x·ln(knee)/knee below the knee, ln(x) above (continuous at the knee)."""
    import math

    lin = x255 * (math.log(knee) / knee)
    return torch.where(x255 <= knee, lin, torch.log(x255.clamp_min(knee)))


def e2nerf_event_loss(
    logs: Tensor, cum_counts: Tensor, c_pos: float = 0.3, c_neg: float = 0.2, offset: float = 0.5
) -> Tensor:
    """E²NeRF / E2GS code's event loss over every pair m < n of the L renders (``../shared/docs/edi-and-events.md``
    §4): estimate (l_n − l_m)/C (0.3 for rising, 0.2 for falling, as the code), target the net count of the interval
    ± ``offset`` (+ on pixels with E ≥ 0, − on E ≤ 0, both terms on E = 0 as E2GS), squared error, mean over pixels
    and pairs. ``logs``: (L, H, W) lin-log intensities; ``cum_counts``: (L, H, W) cumulative counts."""
    n_lat = logs.shape[0]
    terms = []
    for m in range(n_lat):
        for n in range(m + 1, n_lat):
            d = logs[n] - logs[m]
            est = torch.where(d >= 0, d / c_pos, d / c_neg)
            e = (cum_counts[n] - cum_counts[m]).to(d.dtype)
            pos, neg = (e >= 0).to(d.dtype), (e <= 0).to(d.dtype)
            terms.append(((est - (e + offset)) * pos).pow(2).mean() + ((est - (e - offset)) * neg).pow(2).mean())
    if not terms:
        return logs.sum() * 0.0
    return torch.stack(terms).mean()


def normalized_event_loss(log_a: Tensor, log_b: Tensor, counts: Tensor, mask: Tensor | None = None) -> Tensor:
    """BeSplat's / BeNeRF's threshold-free event loss: the predicted log difference and the event count of the
    same interval, each L2-normalised over the pixels, compared by the squared distance ‖Δ/‖Δ‖ − E/‖E‖‖² (summed
    over pixels: 2 − 2·cos of the angle between them, in [0, 4]). Zero when Δ = c·E for any c > 0.

    ``log_a``, ``log_b``: (H, W) log intensities; ``counts``: (H, W) net signed counts; ``mask``: (H, W) bool, True
    where events were ignored. Norms are guarded (≥ 1e-8), so an interval without events or change is finite."""
    diff = log_b - log_a
    e = counts.to(diff.dtype)
    if mask is not None:
        keep = (~mask).to(diff.dtype)
        diff, e = diff * keep, e * keep
    d_hat = diff / diff.norm().clamp_min(1e-8)
    e_hat = e / e.norm().clamp_min(1e-8)
    return (d_hat - e_hat).pow(2).sum()
