"""An ESIM/v2e-style event simulator on a stream of rendered frames.

Model (docs/synthetic.md, "Event simulator"): each pixel keeps a reference log intensity ``ref``. The
log intensity L(t) = ln(Y(t) + ε) (Y: BT.601 luma of the linear image, ε = 1e-3) is taken to vary linearly
between consecutive frames. Every time L crosses ref + C_on the pixel emits an ON event and ref += C_on; every
time it crosses ref − C_off it emits an OFF event and ref −= C_off. Event times are the linearly interpolated
crossing times, floored to integer µs and kept below the step's end: an event of the step from frame time t_i
to t_{i+1} (integer µs) gets a timestamp in [t_i, t_{i+1}), within 1 µs of the exact crossing, so the events
stamped inside an exposure [start, end) are exactly those of its sub-frame steps. Options:

- per-pixel threshold mismatch: C_on, C_off ~ N(C, σ) per pixel, clamped to ≥ ``threshold_min`` (v2e);
- refractory period: an event closer than ``refractory_us`` to the previous *emitted* event of its pixel is
  dropped; the reference still moves (ESIM);
- leak events: the reference drifts down at ``leak_rate_hz``·C_on per second, producing ON events at about
  that rate in static pixels (v2e's leak model); implemented as a linear drift added to L;
- shot noise: Poisson events of random polarity at ``shot_noise_hz`` per pixel, uniform in time; they do
  not move the reference. With ``shot_noise_inten_factor`` f ≠ 1 the rate of a pixel is
  shot_noise_hz·(1 + (f − 1)·inten01), inten01 = (255·Y + 20)/275 from the step's end frame (v2e's
  intensity dependence: f = 0.25 makes dark pixels noisier than bright ones);
- leak options (v2e): ``leak_rate_cov_decades`` spreads the leak rate per pixel log-normally (rate ×
  10^(σ·N(0, 1))); ``leak_random_phase`` starts each pixel a uniform fraction of C_on towards its first leak
  event (a sensor that was already running; otherwise every pixel's first leak event comes at 1/rate);
- hot pixels: a fixed random ``hot_pixel_fraction`` of the pixels fires Poisson events of random polarity at
  ``hot_pixel_rate_hz`` (they do not move the reference).

The invariant −C_off < L − ref < C_on holds after every frame, so all crossings of a step lie inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eigs.errors import EigsError

LOG_EPS = 1e-3  # ε in L = ln(Y + ε)
LUMA_BT601 = np.array([0.299, 0.587, 0.114], dtype=np.float32)


def log_luma(rgb: np.ndarray, eps: float = LOG_EPS) -> np.ndarray:
    """ln(Y + ε) with Y the BT.601 luma of linear RGB in [0, 1]. ``rgb``: (..., 3) → (...) float64."""
    y = np.clip(np.asarray(rgb, dtype=np.float64) @ LUMA_BT601.astype(np.float64), 0.0, None)
    return np.log(y + eps)


@dataclass
class SensorParams:
    """Event sensor parameters. Thresholds in log-intensity units; times in µs; rates in Hz per pixel."""

    contrast_threshold: float = 0.2
    threshold_pos: float | None = None  # None: contrast_threshold
    threshold_neg: float | None = None  # None: contrast_threshold
    threshold_sigma: float = 0.03
    threshold_min: float = 0.01
    refractory_us: float = 100.0
    shot_noise_hz: float = 0.0
    leak_rate_hz: float = 0.0
    shot_noise_inten_factor: float = 1.0
    leak_rate_cov_decades: float = 0.0
    leak_random_phase: bool = False
    hot_pixel_fraction: float = 0.0
    hot_pixel_rate_hz: float = 0.0

    def check(self) -> None:
        for name in ("contrast_threshold", "threshold_min"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise EigsError(None, f"sensor parameter {name} must be a positive number, got {v}")
        for name in ("threshold_pos", "threshold_neg"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise EigsError(None, f"sensor parameter {name} must be a positive number or null, got {v}")
        for name in ("threshold_sigma", "refractory_us", "shot_noise_hz", "leak_rate_hz", "shot_noise_inten_factor",
                     "leak_rate_cov_decades", "hot_pixel_rate_hz"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise EigsError(None, f"sensor parameter {name} must be ≥ 0, got {v}")
        if not 0 <= self.hot_pixel_fraction <= 1:
            raise EigsError(None, "sensor parameter hot_pixel_fraction must lie in [0, 1], got "
                            f"{self.hot_pixel_fraction}")

    @property
    def c_pos(self) -> float:
        return float(self.threshold_pos if self.threshold_pos is not None else self.contrast_threshold)

    @property
    def c_neg(self) -> float:
        return float(self.threshold_neg if self.threshold_neg is not None else self.contrast_threshold)


@dataclass
class EventChunk:
    """Events of one or more steps: x, y (N,) uint16; t (N,) int64 µs (sorted); p (N,) int8 ±1."""

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray

    @staticmethod
    def concat(chunks: list[EventChunk]) -> EventChunk:
        if not chunks:
            return EventChunk(np.zeros(0, np.uint16), np.zeros(0, np.uint16), np.zeros(0, np.int64),
                              np.zeros(0, np.int8))
        return EventChunk(*(np.concatenate([getattr(c, k) for c in chunks]) for k in ("x", "y", "t", "p")))

    def __len__(self) -> int:
        return int(self.t.shape[0])


class EventSimulator:
    """Streaming simulator for an (H, W) sensor. Call :meth:`reset` with the first log frame, then
    :meth:`step` with each following one (strictly increasing times)."""

    def __init__(self, height: int, width: int, params: SensorParams, rng: np.random.Generator):
        params.check()
        self.h, self.w, self.params = int(height), int(width), params
        self.rng = rng
        shape = (self.h, self.w)
        sig = params.threshold_sigma
        self.c_on = np.full(shape, params.c_pos)
        self.c_off = np.full(shape, params.c_neg)
        if sig > 0:
            self.c_on = np.maximum(rng.normal(params.c_pos, sig, shape), params.threshold_min)
            self.c_off = np.maximum(rng.normal(params.c_neg, sig, shape), params.threshold_min)
        # per-pixel leak rate (Hz): v2e's log-normal spread; drawn only when used (keeps older streams identical)
        self.leak_rate: np.ndarray | float = params.leak_rate_hz
        if params.leak_rate_hz > 0 and params.leak_rate_cov_decades > 0:
            self.leak_rate = params.leak_rate_hz * np.exp(
                np.log(10.0) * params.leak_rate_cov_decades * rng.standard_normal(shape))
        self.hot_pixels = np.zeros(0, np.int64)
        if params.hot_pixel_fraction > 0 and params.hot_pixel_rate_hz > 0:
            n_hot = int(round(params.hot_pixel_fraction * self.h * self.w))
            self.hot_pixels = np.sort(rng.choice(self.h * self.w, size=n_hot, replace=False)).astype(np.int64)
        self._phase_pending = bool(params.leak_random_phase and params.leak_rate_hz > 0)
        self.ref = np.zeros(shape)
        self.last_emit = np.full(shape, -np.inf)
        self.L = np.zeros(shape)
        self.t: float | None = None
        self.max_crossings_per_step = 0
        self.crossings = 0
        # histogram of threshold crossings per active pixel per step (last bin: ≥ 64)
        self.crossing_hist = np.zeros(65, np.int64)

    def _drift(self, t_us: float) -> np.ndarray | float:
        """Leak as an upward drift of L (equivalently a downward drift of ref): leak_rate·C_on·t."""
        if self.params.leak_rate_hz == 0:
            return 0.0
        return self.c_on * (self.leak_rate * (t_us * 1e-6))

    def reset(self, log_frame: np.ndarray, t_us: float) -> None:
        """Set every pixel's reference to ``log_frame`` (H, W) at time ``t_us`` (µs). With ``leak_random_phase``
        the first reset puts each reference a uniform fraction u ∈ [0, 1) of C_on below L, so the pixel's first
        leak event comes after (1 − u)/rate instead of 1/rate."""
        L = np.asarray(log_frame, dtype=np.float64) + self._drift(t_us)
        self.ref = L.copy()
        if self._phase_pending:
            self.ref -= self.rng.random(L.shape) * self.c_on
            self._phase_pending = False
        self.L = L
        self.t = float(t_us)

    def step(self, log_frame: np.ndarray, t_us: float) -> EventChunk:
        """Advance to ``log_frame`` (H, W) at ``t_us`` (> the previous time); returns this step's events."""
        if self.t is None:
            raise RuntimeError("EventSimulator.step called before reset")
        t0, t1 = self.t, float(t_us)
        if not t1 > t0:
            raise ValueError(f"frame times must increase ({t1} after {t0})")
        L0 = self.L
        L1 = np.asarray(log_frame, dtype=np.float64) + self._drift(t1)
        ref = self.ref
        n_on = np.floor((L1 - ref) / self.c_on)
        n_off = np.floor((ref - L1) / self.c_off)
        n_on = np.where(n_on > 0, n_on, 0).astype(np.int64)
        n_off = np.where(n_off > 0, n_off, 0).astype(np.int64)
        n = n_on + n_off  # only one of them is non-zero per pixel (invariant)
        flat = np.flatnonzero(n)
        chunks: list[EventChunk] = []
        if flat.size:
            cnt = n.ravel()[flat]
            total = int(cnt.sum())
            self.crossings += total
            self.max_crossings_per_step = max(self.max_crossings_per_step, int(cnt.max()))
            self.crossing_hist += np.bincount(np.minimum(cnt, 64), minlength=65)
            pix = np.repeat(flat, cnt)
            k = np.arange(total) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1  # 1..n per pixel
            pos = n_on.ravel()[pix] > 0
            c = np.where(pos, self.c_on.ravel()[pix], -self.c_off.ravel()[pix])
            level = ref.ravel()[pix] + k * c
            a, b = L0.ravel()[pix], L1.ravel()[pix]
            diff = b - a
            frac = np.where(np.abs(diff) > 0, (level - a) / np.where(diff == 0, 1.0, diff), 1.0)
            te = t0 + np.clip(frac, 0.0, 1.0) * (t1 - t0)
            keep = np.ones(total, dtype=bool)
            refr = self.params.refractory_us
            if refr > 0:
                last = self.last_emit.ravel()
                for kk in range(1, int(cnt.max()) + 1):
                    sel = np.flatnonzero(k == kk)
                    p_sel = pix[sel]
                    ok = te[sel] - last[p_sel] >= refr
                    keep[sel] = ok
                    last[p_sel[ok]] = te[sel][ok]
            pix, te, pos = pix[keep], te[keep], pos[keep]
            chunks.append(
                EventChunk((pix % self.w).astype(np.uint16), (pix // self.w).astype(np.uint16), te,
                           np.where(pos, 1, -1).astype(np.int8))
            )
            self.ref = ref + n_on * self.c_on - n_off * self.c_off
        rate = self.params.shot_noise_hz
        f = self.params.shot_noise_inten_factor
        if rate > 0 and f == 1.0:
            m = int(self.rng.poisson(rate * self.h * self.w * (t1 - t0) * 1e-6))
            if m:
                pix = self.rng.integers(0, self.h * self.w, m)
                chunks.append(self._random_events(pix, t0, t1))
        elif rate > 0:
            # thinning: candidates at the largest rate, each kept with probability rate(pixel)/largest rate
            peak = rate * max(1.0, f)
            m = int(self.rng.poisson(peak * self.h * self.w * (t1 - t0) * 1e-6))
            if m:
                pix = self.rng.integers(0, self.h * self.w, m)
                y_lin = np.clip(np.exp(np.asarray(log_frame, np.float64).ravel()[pix]) - LOG_EPS, 0.0, 1.0)
                inten01 = (255.0 * y_lin + 20.0) / 275.0
                keep = self.rng.random(m) * peak < rate * (1.0 + (f - 1.0) * inten01)
                if keep.any():
                    chunks.append(self._random_events(pix[keep], t0, t1))
        if self.hot_pixels.size:
            k = self.rng.poisson(self.params.hot_pixel_rate_hz * (t1 - t0) * 1e-6, self.hot_pixels.size)
            if k.any():
                chunks.append(self._random_events(np.repeat(self.hot_pixels, k), t0, t1))
        self.L, self.t = L1, t1
        out = EventChunk.concat(chunks)
        if len(out):
            order = np.argsort(out.t, kind="stable")
            # ⌊crossing time⌋, kept inside [t0, t1): a step's events never share the next frame's timestamp
            last_us = np.ceil(t1) - 1.0
            t_int = np.minimum(np.floor(out.t[order]), last_us).astype(np.int64)
            out = EventChunk(out.x[order], out.y[order], t_int, out.p[order])
        else:
            out.t = out.t.astype(np.int64)
        return out


    def _random_events(self, pix: np.ndarray, t0: float, t1: float) -> EventChunk:
        """Noise events at flat pixel indices ``pix``: times uniform in [t0, t1) µs, polarity ±1 with equal odds."""
        m = pix.size
        te = self.rng.uniform(t0, t1, m)
        p = np.where(self.rng.random(m) < 0.5, 1, -1).astype(np.int8)
        return EventChunk((pix % self.w).astype(np.uint16), (pix // self.w).astype(np.uint16), te, p)


def simulate(
    log_frames: np.ndarray,
    t_us: np.ndarray,
    params: SensorParams,
    rng: np.random.Generator | None = None,
    *,
    reset_times_us: np.ndarray | None = None,
) -> tuple[EventChunk, EventSimulator]:
    """Run the simulator over a whole stream. ``log_frames``: (T, H, W) log intensity; ``t_us``: (T,) increasing
    µs. The reference is set from frame 0, and again at every frame whose time is in ``reset_times_us``.
    Returns all events (sorted by time) and the simulator (its thresholds ``c_on``/``c_off``, counters)."""
    log_frames = np.asarray(log_frames, dtype=np.float64)
    sim = EventSimulator(log_frames.shape[1], log_frames.shape[2], params, rng or np.random.default_rng(0))
    sim.reset(log_frames[0], float(t_us[0]))
    resets = set(np.asarray(reset_times_us if reset_times_us is not None else [], dtype=np.int64).tolist())
    chunks = []
    for i in range(1, log_frames.shape[0]):
        chunks.append(sim.step(log_frames[i], float(t_us[i])))
        if int(t_us[i]) in resets:
            sim.reset(log_frames[i], float(t_us[i]))
    return EventChunk.concat(chunks), sim
