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
  not move the reference.

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

    def check(self) -> None:
        for name in ("contrast_threshold", "threshold_min"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise EigsError(None, f"sensor parameter {name} must be a positive number, got {v}")
        for name in ("threshold_pos", "threshold_neg"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise EigsError(None, f"sensor parameter {name} must be a positive number or null, got {v}")
        for name in ("threshold_sigma", "refractory_us", "shot_noise_hz", "leak_rate_hz"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise EigsError(None, f"sensor parameter {name} must be ≥ 0, got {v}")

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
        rate = self.params.leak_rate_hz
        return 0.0 if rate == 0 else self.c_on * (rate * t_us * 1e-6)

    def reset(self, log_frame: np.ndarray, t_us: float) -> None:
        """Set every pixel's reference to ``log_frame`` (H, W) at time ``t_us`` (µs)."""
        L = np.asarray(log_frame, dtype=np.float64) + self._drift(t_us)
        self.ref = L.copy()
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
        if rate > 0:
            m = int(self.rng.poisson(rate * self.h * self.w * (t1 - t0) * 1e-6))
            if m:
                pix = self.rng.integers(0, self.h * self.w, m)
                te = self.rng.uniform(t0, t1, m)
                p = np.where(self.rng.random(m) < 0.5, 1, -1).astype(np.int8)
                chunks.append(EventChunk((pix % self.w).astype(np.uint16), (pix // self.w).astype(np.uint16), te, p))
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
