"""Per-pixel contrast-threshold calibration for the estimated EDI mode (``docs/edi.md``, "Per-pixel thresholds").

A real (or v2e-simulated) sensor has a fixed pattern of thresholds: pixel p fires an ON event per c⁺_p and an OFF
event per c⁻_p of log-intensity change. EDI with one global c leaves each latent log intensity off by
δc_p·(event integral), a speckle. The thresholds are identifiable because the events run continuously across the
whole recording: for consecutive exposures v, v+1 and every pixel (ref = exposure start, E(t; c) = c⁺N⁺(t) −
c⁻N⁻(t), b_v = ln(luma(B_v) + ε), log M_v(c) = ln mean_exposure exp(E_v(s; c))):

    ℓ_v(end)       = b_v − log M_v(c) + E_v(end; c)
    ℓ_{v+1}(start) = b_{v+1} − log M_{v+1}(c)
    ℓ_{v+1}(start) − ℓ_v(end) = c⁺·G⁺_v − c⁻·G⁻_v          (G: the events of the gap)

so the gap residual r_v(c) = (b_{v+1} − b_v) − (c⁺N⁺_v − c⁻N⁻_v) − log M_{v+1}(c) + log M_v(c), with N the events
from start_v to start_{v+1}, must vanish. Per pixel, (c⁺, c⁻) minimise Σ_v ω_v ρ(r_v) + λ|c − c̄|² by
Gauss–Newton with Huber IRLS weights (:func:`calibrate`): ω_v from the 8-bit quantisation of both blurry frames
(dark pixels weigh little, saturated ones nothing) plus a model floor; the prior λ shrinks pixels with little
evidence towards a centre c̄: first the global threshold, then the median of the maps over the pixels whose data
carry ≥ :data:`STRONG_EVIDENCE` × the prior's information (one (c⁺, c⁻) fitted to all pixels was biased: 0.11
on `chair` against a true 0.2); results are clamped to [c̄/:data:`CLAMP`, c̄·:data:`CLAMP`]. Differencing per
gap (instead of fitting absolute log intensities) keeps an event lost in one gap (refractory period, noise) an
outlier of one residual rather than an offset of all later ones.

:class:`PolarityIntegral` is :class:`~eigs.edi.edi.ExposureIntegral` with the two polarities kept apart, so
log M and its derivatives can be evaluated for per-pixel (c⁺, c⁻) maps in O(N + H·W).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from eigs.edi.binning import polarity_counts
from eigs.edi.edi import EXP_CLIP, LOG_EPS, exposure_events, luma, pixel_segments
from eigs.util.image import srgb_to_linear

log = logging.getLogger(__name__)

MIN_GAPS = 4  # fewer usable gaps (consecutive exposure pairs with gap events): fall back to the global threshold
CLAMP = 2.5  # per-pixel thresholds lie in [c̄ / CLAMP, c̄ · CLAMP]
PRIOR_SIGMA = 0.05  # prior std of a pixel's threshold around the centre (log-intensity units)
MODEL_SIGMA = 0.05  # model noise floor of a gap residual (event quantisation, noise), log units
HUBER_K = 2.0  # Huber threshold in units of the residual's σ
ITERATIONS = 8
MIN_STRONG = 50  # pixels with more data than prior information needed to re-centre the prior
STRONG_EVIDENCE = 10.0  # pixels whose data carry this many times the prior information set the prior centre
MAX_STEP = 0.05  # largest change of a threshold per Gauss–Newton iteration


class PolarityIntegral:
    """One exposure's exact per-pixel event integral with ON and OFF counts apart (reference = ``start``).

    For a pixel with thresholds (c⁺, c⁻): E(t) = c⁺·N⁺(t) − c⁻·N⁻(t), N^± counted from ``start``, piecewise
    constant between events; M = Σ_segments (duration / T)·exp(E_segment). ``x``, ``y``, ``t``, ``p``: the events
    (time-sorted; those outside [start, end) are dropped); ``mask``: optional (H, W) bool, True = ignore."""

    def __init__(self, x, y, t, p, start: int, end: int, height: int, width: int, mask=None):
        self.height, self.width = int(height), int(width)
        q, t, p = exposure_events(x, y, t, p, start, end, width, mask)
        self.n_events = int(q.shape[0])
        seg = pixel_segments(q, t, start, end)
        if seg is None:
            self.pix = np.zeros(0, np.int64)
            return
        order, gstart, gid, seg_init, seg_evt, dur, seg_len = seg
        on = p[order] > 0
        cpos = np.cumsum(on.astype(np.int64))
        cneg = np.cumsum((~on).astype(np.int64))
        npos = np.zeros(dur.shape[0], np.int32)
        nneg = np.zeros(dur.shape[0], np.int32)
        npos[seg_evt] = cpos - (cpos[gstart] - on[gstart])[gid]  # counts from the start up to and including
        nneg[seg_evt] = cneg - (cneg[gstart] - (~on[gstart]))[gid]
        self.pix = q[order][gstart]
        self.seg_start = seg_init
        self.seg_pos, self.seg_neg = npos, nneg
        self.seg_w = dur.astype(np.float64) / max(int(end) - int(start), 1)
        self._rep = seg_len
        self._seg_pix = np.repeat(self.pix, self._rep)

    def log_mean_exp(self, c_pos: np.ndarray, c_neg: np.ndarray, grad: bool = False):
        """log M for per-pixel threshold maps ``c_pos``, ``c_neg`` (H, W) → (H, W) float64 (0 where no events).
        With ``grad``: also (m⁺, m⁻) = (∂ log M/∂c⁺, −∂ log M/∂c⁻), the exp-weighted mean ON and OFF counts."""
        hw = self.height * self.width
        out = np.zeros(hw, np.float64)
        mp, mn = np.zeros(hw, np.float64), np.zeros(hw, np.float64)
        if self.pix.shape[0]:
            cp = np.asarray(c_pos, np.float64).reshape(-1)[self._seg_pix]
            cn = np.asarray(c_neg, np.float64).reshape(-1)[self._seg_pix]
            v = np.clip(cp * self.seg_pos - cn * self.seg_neg, -EXP_CLIP, EXP_CLIP)
            v = np.where(self.seg_w > 0, v, -np.inf)
            m = np.maximum.reduceat(v, self.seg_start)
            e = self.seg_w * np.exp(v - np.repeat(m, self._rep))
            s = np.add.reduceat(e, self.seg_start)  # ≥ the max segment's weight > 0
            out[self.pix] = m + np.log(s)
            if grad:
                mp[self.pix] = np.add.reduceat(e * self.seg_pos, self.seg_start) / s
                mn[self.pix] = np.add.reduceat(e * self.seg_neg, self.seg_start) / s
        shape = (self.height, self.width)
        if grad:
            return out.reshape(shape), mp.reshape(shape), mn.reshape(shape)
        return out.reshape(shape)


def counts_before(x, y, t, p, start: int, times: np.ndarray, height: int, width: int, mask=None):
    """(ON, OFF) counts of the events with ``start`` ≤ t < times[k], for each k: two (L, H, W) float64.
    ``times``: (L,) strictly increasing, times[0] ≥ ``start``."""
    times = np.asarray(times, dtype=np.int64)
    if times[0] > start:  # a first bin [start, times[0])
        on, off = polarity_counts(x, y, t, p, np.concatenate([[start], times]), height, width, mask)
    else:  # nothing before times[0] = start
        on, off = polarity_counts(x, y, t, p, times, height, width, mask)
        zero = np.zeros((1, height, width), np.int64)
        on, off = np.concatenate([zero, on]), np.concatenate([zero, off])
    return np.cumsum(on, axis=0).astype(np.float64), np.cumsum(off, axis=0).astype(np.float64)


def log_luma_and_sigma(blurry_u8: np.ndarray, response: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For an 8-bit frame (H, W, C): b = ln(luma(Y) + ε) of the linearised frame, its quantisation σ (half a code
    step up and down in every channel, /√12) and a (H, W) bool 'saturated' (some channel at 255)."""
    u = np.asarray(blurry_u8, dtype=np.float64)

    def lin(v: np.ndarray) -> np.ndarray:
        v = np.clip(v, 0.0, 255.0) / 255.0
        return srgb_to_linear(v) if response == "srgb" else v

    b = np.log(np.maximum(luma(lin(u)), 0.0) + LOG_EPS)
    hi = np.log(np.maximum(luma(lin(u + 0.5)), 0.0) + LOG_EPS)
    lo = np.log(np.maximum(luma(lin(u - 0.5)), 0.0) + LOG_EPS)
    sat = np.any(u >= 254.5, axis=-1)
    return b, (hi - lo) / np.sqrt(12.0), sat


@dataclass
class Calibration:
    """Per-pixel thresholds: ``c_pos``, ``c_neg`` (H, W) float64; ``pooled``: the pooled (c⁺, c⁻);
    ``evidence``: (H, W) Σ of the data weights (information about the pixel's thresholds, relative to the prior);
    ``n_gaps``: gaps used; ``median_abs_residual`` before and after (log units)."""

    c_pos: np.ndarray
    c_neg: np.ndarray
    pooled: tuple[float, float]
    evidence: np.ndarray
    n_gaps: int
    residual_before: float
    residual_after: float


def usable_gaps(t_sorted: np.ndarray, exposure_us: np.ndarray) -> np.ndarray:
    """(V − 1,) bool: gap v (end_v … start_{v+1}) has events recorded in it, or no length at all. A stream cut to
    the exposures (``--keep-events exposures``) has none."""
    exp = np.asarray(exposure_us, np.int64)
    if exp.shape[0] < 2:
        return np.zeros(0, bool)
    a = np.searchsorted(t_sorted, exp[:-1, 1], side="left")
    b = np.searchsorted(t_sorted, exp[1:, 0], side="left")
    return usable_gaps_from_counts(a, b, exp)


def usable_gaps_from_counts(before_end: np.ndarray, before_next: np.ndarray, exposure_us: np.ndarray) -> np.ndarray:
    """:func:`usable_gaps` from counts alone: ``before_end`` (V − 1,) events with t < end_v, ``before_next``
    (V − 1,) events with t < start_{v+1} (a view index holds both), so a stream need not be read."""
    exp = np.asarray(exposure_us, np.int64)
    if exp.shape[0] < 2:
        return np.zeros(0, bool)
    ok = (np.asarray(before_next) > np.asarray(before_end)) | (exp[1:, 0] <= exp[:-1, 1])
    return ok & (exp[1:, 0] > exp[:-1, 0])


def calibrate(
    b: np.ndarray,
    sigma_b: np.ndarray,
    saturated: np.ndarray,
    integrals: list[PolarityIntegral],
    n_pos: np.ndarray,
    n_neg: np.ndarray,
    gaps: np.ndarray,
    c0: float,
    mask: np.ndarray | None = None,
    iterations: int = ITERATIONS,
    prior_sigma: float = PRIOR_SIGMA,
) -> Calibration:
    """Fit per-pixel (c⁺, c⁻) from the gap residuals (module docstring).

    ``b``, ``sigma_b``, ``saturated``: (V, H, W) from :func:`log_luma_and_sigma`; ``integrals``: V
    :class:`PolarityIntegral` (reference = exposure start); ``n_pos``, ``n_neg``: (V − 1, H, W) events from
    start_v to start_{v+1}; ``gaps``: (V − 1,) bool usable; ``c0``: the global threshold (start and fallback);
    ``mask``: (H, W) True = pixel without events (hot): it gets the centre values."""
    v_n, h, w = b.shape
    gidx = np.flatnonzero(gaps)
    npos = n_pos[gidx].astype(np.float64)
    nneg = n_neg[gidx].astype(np.float64)
    db = b[gidx + 1] - b[gidx]
    var = sigma_b[gidx] ** 2 + sigma_b[gidx + 1] ** 2 + MODEL_SIGMA**2
    omega = np.where(saturated[gidx] | saturated[gidx + 1], 0.0, 1.0 / var)
    if mask is not None:
        omega = omega * ~mask[None]
    need = np.unique(np.concatenate([gidx, gidx + 1]))
    sig = np.sqrt(var)

    def residuals(cp: np.ndarray, cn: np.ndarray, grad: bool):
        lm, mp, mn = {}, {}, {}
        for v in need:
            r = integrals[v].log_mean_exp(cp, cn, grad=grad)
            if grad:
                lm[v], mp[v], mn[v] = r
            else:
                lm[v] = r
        res = np.empty((gidx.size, h, w))
        jp = np.empty((gidx.size, h, w)) if grad else None
        jn = np.empty((gidx.size, h, w)) if grad else None
        for i, v in enumerate(gidx):
            res[i] = db[i] - (cp * npos[i] - cn * nneg[i]) - lm[v + 1] + lm[v]
            if grad:
                jp[i] = -npos[i] - mp[v + 1] + mp[v]
                jn[i] = nneg[i] + mn[v + 1] - mn[v]
        return res, jp, jn

    def weights(res: np.ndarray) -> np.ndarray:
        z = np.abs(res) / sig
        return omega * np.where(z > HUBER_K, HUBER_K / np.maximum(z, 1e-12), 1.0)

    def solve(a11, a12, a22, g1, g2):
        det = a11 * a22 - a12 * a12
        det = np.where(np.abs(det) > 1e-300, det, 1e-300)
        return (a22 * g1 - a12 * g2) / det, (a11 * g2 - a12 * g1) / det

    def fit(cp, cn, cen_p, cen_n, iters):
        lam = 1.0 / prior_sigma**2
        evidence = np.zeros((h, w))
        for _ in range(iters):
            res, jp, jn = residuals(cp, cn, True)
            wt = weights(res)
            a11 = (wt * jp * jp).sum(0) + lam
            a12 = (wt * jp * jn).sum(0)
            a22 = (wt * jn * jn).sum(0) + lam
            g1 = (wt * jp * res).sum(0) + lam * (cp - cen_p)
            g2 = (wt * jn * res).sum(0) + lam * (cn - cen_n)
            d1, d2 = solve(a11, a12, a22, -g1, -g2)
            d1 = np.where(np.isfinite(d1), np.clip(d1, -MAX_STEP, MAX_STEP), 0.0)
            d2 = np.where(np.isfinite(d2), np.clip(d2, -MAX_STEP, MAX_STEP), 0.0)
            cp = np.clip(cp + d1, cen_p / CLAMP, cen_p * CLAMP)
            cn = np.clip(cn + d2, cen_n / CLAMP, cen_n * CLAMP)
            evidence = (a11 + a22) / (2 * lam) - 1.0
        return cp, cn, evidence

    # ---- stage 1: per pixel, shrunk towards c0; the centre = median over the pixels the data determine
    res0, _, _ = residuals(np.full((h, w), c0), np.full((h, w), c0), False)
    cp, cn, evidence = fit(np.full((h, w), c0), np.full((h, w), c0), c0, c0, iterations)
    strong = evidence >= STRONG_EVIDENCE
    if mask is not None:
        strong &= ~mask
    cen_p = cen_n = float(c0)
    if strong.sum() >= max(MIN_STRONG, 0.01 * h * w):
        cen_p, cen_n = float(np.median(cp[strong])), float(np.median(cn[strong]))
        # ---- stage 2: shrink towards the data's own centre
        cp, cn, evidence = fit(np.clip(cp, cen_p / CLAMP, cen_p * CLAMP), np.clip(cn, cen_n / CLAMP, cen_n * CLAMP),
                               cen_p, cen_n, max(iterations // 2, 1))
    cp_s, cn_s = cen_p, cen_n
    res1, _, _ = residuals(cp, cn, False)
    sel = omega > 0
    before = float(np.median(np.abs(res0[sel]))) if sel.any() and res0 is not None else float("nan")
    after = float(np.median(np.abs(res1[sel]))) if sel.any() else float("nan")
    if mask is not None:
        cp = np.where(mask, cp_s, cp)
        cn = np.where(mask, cn_s, cn)
    return Calibration(cp, cn, (cp_s, cn_s), evidence, int(gidx.size), before, after)


def edi_per_pixel(
    blurry_linear: np.ndarray,
    s_pos: np.ndarray,
    s_neg: np.ndarray,
    log_mean: np.ndarray,
    c_pos: np.ndarray,
    c_neg: np.ndarray,
    eps: float = LOG_EPS,
) -> np.ndarray:
    """Latent frames with per-pixel thresholds: (Y_k + ε) = (Y_blur + ε)·exp(c⁺S⁺_k − c⁻S⁻_k − log M).

    ``s_pos``, ``s_neg``: (L, H, W) ON/OFF counts from the exposure start to each latent time; ``log_mean``: (H, W)
    from :meth:`PolarityIntegral.log_mean_exp` (same maps). Returns (L, H, W, C) float64 linear, not clipped."""
    log_f = c_pos[None] * s_pos - c_neg[None] * s_neg - log_mean[None]
    log_f = np.clip(np.where(np.isfinite(log_f), log_f, 0.0), -EXP_CLIP, EXP_CLIP)
    return (np.asarray(blurry_linear, np.float64) + eps)[None] * np.exp(log_f)[..., None] - eps
