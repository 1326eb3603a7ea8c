"""Event Double Integral (EDI): latent sharp frames from one blurry frame and its events.

Two modes (formulas and derivations in ``docs/edi.md``):

- **E²NeRF exact** (:func:`edi_e2nerf`): the discrete model on 0–255 pixel values with c = 0.3, exactly as
  E²NeRF's ``EDI.py`` computes it, but with the denominator in log space (stable log-sum-exp).
- **Estimated** (:func:`edi_discrete`, :class:`ExposureIntegral`): linear intensity Y with the simulator's offset,
  log(Y + ε) = log(Y_ref + ε) + c·E(t). With raw timestamps the exposure average of exp(c·E(t)) is integrated
  exactly over the piecewise-constant event integral of every pixel (continuous-time double integral);
  with pre-binned events the discrete B + 1-frame average is used.

Every function is NaN/Inf-free for any counts, any c ≥ 0 and black or saturated pixels: exponents are built in
float64 log space and clipped to ±:data:`EXP_CLIP` before ``exp``.
"""

from __future__ import annotations

import numpy as np

from eigs.util.image import linear_to_srgb, srgb_to_linear

EXP_CLIP = 700.0  # |exponent| bound before exp() in float64 (exp(700) ≈ 1e304, finite)
LOG_EPS = 1e-3  # ε of the log-intensity model ln(Y + ε), Y linear in [0, 1] (the synthetic simulator's value)
E2NERF_C = 0.3  # E²NeRF's fixed contrast threshold


# -------------------------------------------------------------------------------------------- domains
def to_linear(image_u8: np.ndarray, response: str) -> np.ndarray:
    """uint8 frame → float64 linear intensity in [0, 1]. ``response``: ``linear`` or ``unknown`` (taken as linear,
    like a raw APS readout) or ``srgb``."""
    v = np.asarray(image_u8, dtype=np.float64) / 255.0
    return srgb_to_linear(v) if response == "srgb" else v


def from_linear(linear: np.ndarray, response: str) -> np.ndarray:
    """Inverse of :func:`to_linear` (without the ×255): linear [0, 1] → the scene's pixel domain in [0, 1]."""
    v = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    return linear_to_srgb(v) if response == "srgb" else v


def luma(image: np.ndarray) -> np.ndarray:
    """(…, H, W, C) → (…, H, W) BT.601 luma (C = 3) or the single channel (C = 1)."""
    image = np.asarray(image)
    if image.shape[-1] == 1:
        return image[..., 0]
    return image[..., 0] * 0.299 + image[..., 1] * 0.587 + image[..., 2] * 0.114


# -------------------------------------------------------------------------------------------- log-sum-exp
def logsumexp(a: np.ndarray, axis: int = 0) -> np.ndarray:
    """Stable log Σ exp(a) along ``axis`` (finite for finite ``a``)."""
    a = np.asarray(a, dtype=np.float64)
    m = a.max(axis=axis, keepdims=True)
    return np.squeeze(m, axis=axis) + np.log(np.exp(a - m).sum(axis=axis))


def _safe_exp(a: np.ndarray) -> np.ndarray:
    return np.exp(np.clip(a, -EXP_CLIP, EXP_CLIP))


# -------------------------------------------------------------------------------------------- discrete EDI
def edi_e2nerf(blurry_255: np.ndarray, cum_counts: np.ndarray, c: float = E2NERF_C) -> np.ndarray:
    """E²NeRF's EDI on 0–255 values (edi-and-events.md §2.3).

    With S_k = ``cum_counts[k]`` (S_0 = 0): D = Σ_{k=0..B} exp(c·S_k), I_0 = min(255, (B+1)·I_blur / D),
    I_k = I_0 · exp(c·S_k). The product is formed in log space, log I_k = min(log 255, log(n·I) − log D) + c·S_k
    with log D by log-sum-exp, so c·S beyond the range of exp neither overflows nor loses the frame (exp(c·S_k)
    and 1/D cancel before exp is taken).

    ``blurry_255``: (H, W, C) values in [0, 255] (uint8 or float); ``cum_counts``: (B + 1, H, W) signed counts.
    Returns (B + 1, H, W, C) float64, I_0 ≤ 255, the other frames not clamped (they may exceed 255, up to
    exp(:data:`EXP_CLIP`)); black pixels stay exactly 0.
    """
    s = np.asarray(cum_counts, dtype=np.float64) * float(c)  # (L, H, W)
    n = s.shape[0]
    log_d = logsumexp(s, axis=0)  # ≥ 0 because S_0 = 0
    blur = np.asarray(blurry_255, dtype=np.float64)
    with np.errstate(divide="ignore"):  # log 0 = −inf: black pixels give exp(−inf) = 0
        log_i0 = np.minimum(np.log(255.0), np.log(n * blur) - log_d[..., None])  # (H, W, C) log I_0
    return np.exp(np.minimum(log_i0[None] + s[..., None], EXP_CLIP))


def edi_discrete(
    blurry_linear: np.ndarray,
    cum_counts: np.ndarray,
    c: float,
    eps: float = LOG_EPS,
    at: np.ndarray | None = None,
) -> np.ndarray:
    """Estimated-mode EDI from binned events (the B + 1-frame average model) in linear intensity.

    (Y_k + ε) = (B+1)·(Y_blur + ε)·exp(c·S_k) / Σ_j exp(c·S_j), per channel with one factor per pixel.
    ``blurry_linear``: (H, W, C) in [0, 1]; ``cum_counts``: (B + 1, H, W). Returns (B + 1, H, W, C) float64
    linear intensity, not clipped (clip at storage). ``at``: optional (K, H, W) event integrals (from latent time 0)
    of other times to return the frames at instead.
    """
    s = np.asarray(cum_counts, dtype=np.float64) * float(c)
    n = s.shape[0]
    s_at = s if at is None else np.asarray(at, dtype=np.float64) * float(c)
    log_f = s_at - logsumexp(s, axis=0)[None] + np.log(n)  # (K, H, W) log of the per-pixel factor
    return (np.asarray(blurry_linear, np.float64) + eps)[None] * _safe_exp(log_f)[..., None] - eps


def exposure_events(x, y, t, p, start: int, end: int, width: int, mask=None) -> tuple[np.ndarray, ...]:
    """Events with start ≤ t < end, off masked pixels (``mask`` (H, W) bool, True = ignore): flat pixel index
    q = y·width + x, t and p, each (N,) int64, in their input order."""
    t = np.asarray(t, dtype=np.int64)
    q = np.asarray(y, dtype=np.int64) * width + np.asarray(x, dtype=np.int64)
    keep = (t >= start) & (t < end)
    if mask is not None:
        keep &= ~np.asarray(mask, dtype=bool).reshape(-1)[q]
    return q[keep], t[keep], np.asarray(p, dtype=np.int64)[keep]


def pixel_segments(q: np.ndarray, t: np.ndarray, start: int, end: int) -> tuple[np.ndarray, ...] | None:
    """Group one exposure's events by pixel into the segments on which a pixel's event count is constant.

    ``q``, ``t``: (N,) flat pixel index and time (time-sorted) of events inside [start, end). Per active pixel
    j (G of them) the segments are [start, first event) and then [event i, next event of the pixel or end) for
    each of its events: N + G segments, a pixel's contiguous, the pixels in ascending q. Returns None without
    events, else ``order`` (N,) (events sorted by pixel, time order kept), ``gstart`` (G,) first sorted event of
    each pixel, ``gid`` (N,) pixel group of each sorted event, ``seg_init`` (G,) index of each pixel's first
    segment, ``seg_evt`` (N,) index of the segment starting at each sorted event, ``duration`` (N + G,) int64
    segment lengths (µs), ``seg_len`` (G,) segments per pixel."""
    order = np.argsort(q, kind="stable")  # events stay time-ordered within each pixel
    qs, ts = q[order], t[order]
    n = qs.shape[0]
    if n == 0:
        return None
    new = np.ones(n, dtype=bool)
    new[1:] = qs[1:] != qs[:-1]
    gstart = np.flatnonzero(new)
    g = gstart.shape[0]
    gid = np.cumsum(new) - 1
    seg_init = gstart + np.arange(g)
    seg_evt = np.arange(n) + gid + 1
    nxt = np.empty(n, np.int64)
    nxt[:-1] = ts[1:]
    nxt[np.append(gstart[1:] - 1, n - 1)] = end
    duration = np.empty(n + g, np.int64)
    duration[seg_evt] = nxt - ts
    duration[seg_init] = ts[gstart] - start
    seg_len = np.diff(np.append(gstart, n)) + 1
    return order, gstart, gid, seg_init, seg_evt, duration, seg_len


class ExposureIntegral:
    """The exact per-pixel event integral of one exposure, for the continuous-time double integral.

    For a pixel, E(t) = Σ_{t_i < t} p_i − Σ_{t_i < t_ref} p_i is piecewise constant between its events, so

        M(c) = (1/T) ∫_start^end exp(c·E(t)) dt = Σ_segments (duration / T) · exp(c · E_segment)

    is evaluated exactly, as a weighted log-sum-exp over segments (:meth:`log_mean_exp`). The segment structure is
    built once (one stable sort of the view's events by pixel), then every c costs O(N + H·W).

    ``x``, ``y``, ``t``, ``p``: (N,) events (t int64 µs, any order within the exposure is fine as long as it is
    time-sorted; events outside [start, end) are dropped); ``t_ref``: the reference time (latent time 0);
    ``mask``: optional (H, W) bool, True = ignore the pixel's events.
    """

    def __init__(
        self,
        x: np.ndarray,
        y: np.ndarray,
        t: np.ndarray,
        p: np.ndarray,
        start: int,
        end: int,
        t_ref: int,
        height: int,
        width: int,
        mask: np.ndarray | None = None,
    ):
        self.height, self.width = int(height), int(width)
        q, t, p = exposure_events(x, y, t, p, start, end, width, mask)
        self.n_events = int(q.shape[0])
        seg = pixel_segments(q, t, start, end)
        if seg is None:
            self.pix = np.zeros(0, np.int64)
            self.seg_start = np.zeros(0, np.int64)
            self.seg_val = np.zeros(0, np.float64)
            self.seg_w = np.zeros(0, np.float64)
            self._rep = np.zeros(0, np.int64)
            return
        order, gstart, gid, seg_init, seg_evt, dur, seg_len = seg
        ts, ps = t[order], p[order]
        cs = np.cumsum(ps)
        after = cs - (cs[gstart] - ps[gstart])[gid]  # count from exposure start up to and including the event
        before_ref = np.add.reduceat(np.where(ts < t_ref, ps, 0), gstart)  # (G,) E at t_ref from the start
        val = np.empty(dur.shape[0], np.int64)
        val[seg_init] = 0
        val[seg_evt] = after
        val -= np.repeat(before_ref, seg_len)
        self.pix = q[order][gstart]
        self.seg_start = seg_init
        self.seg_val = val.astype(np.float64)
        self.seg_w = dur.astype(np.float64) / max(int(end) - int(start), 1)
        self._rep = seg_len

    def log_mean_exp(self, c: float) -> np.ndarray:
        """(H, W) float64 log M(c) = log((1/T)∫ exp(c·E(t)) dt); 0 at pixels without events."""
        out = np.zeros(self.height * self.width, np.float64)
        if self.pix.shape[0]:
            v = self.seg_val * float(c)
            v = np.where(self.seg_w > 0, v, -np.inf)  # zero-length segments (simultaneous events) carry no weight
            m = np.maximum.reduceat(v, self.seg_start)
            s = np.add.reduceat(self.seg_w * np.exp(v - np.repeat(m, self._rep)), self.seg_start)
            out[self.pix] = m + np.log(s)  # s ≥ the max segment's weight > 0
        return out.reshape(self.height, self.width)


def edi_continuous(
    blurry_linear: np.ndarray,
    cum_counts: np.ndarray,
    log_mean: np.ndarray,
    c: float,
    eps: float = LOG_EPS,
) -> np.ndarray:
    """Latent frames of the continuous model: (Y_k + ε) = (Y_blur + ε) · exp(c·E(t_k) − log M(c)).

    ``blurry_linear``: (H, W, C) in [0, 1]; ``cum_counts``: (L, H, W) E(t_k) relative to latent time 0;
    ``log_mean``: (H, W) from :meth:`ExposureIntegral.log_mean_exp` (same c, same reference time).
    Returns (L, H, W, C) float64 linear intensity, not clipped.
    """
    log_f = np.asarray(cum_counts, dtype=np.float64) * float(c) - log_mean[None]
    return (np.asarray(blurry_linear, np.float64) + eps)[None] * _safe_exp(log_f)[..., None] - eps


def blur_extent_px(latent: np.ndarray) -> float:
    """Estimated blur extent (px) of a view: the displacement between its first and last latent frames, by phase
    correlation of their luma (Hann window). ``latent``: (L, H, W, C) in [0, 1]. 0 for constant frames."""
    import cv2

    a = luma(latent[0]).astype(np.float32)
    b = luma(latent[-1]).astype(np.float32)
    if a.shape[0] < 8 or a.shape[1] < 8 or np.ptp(a) == 0 or np.ptp(b) == 0:
        return 0.0
    win = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), _ = cv2.phaseCorrelate(a - a.mean(), b - b.mean(), win)
    d = float(np.hypot(dx, dy))
    return d if np.isfinite(d) else 0.0
