"""Two clocks, one view: frames and events recorded by two devices (a beam-splitter rig, or a hybrid sensor whose
frame and event parts keep separate clocks), brought onto the event sensor's pixel grid and clock.

- **Homography** (``--frames-homography FILE``): a 3×3 matrix H mapping **frame pixels to event pixels**,
  x_event ~ H · (x_frame, y_frame, 1)ᵀ, both in OpenCV pixel coordinates (the centre of the top-left pixel at
  (0, 0)), as ``cv2.findHomography(frame_points, event_points)`` returns it. The frames are warped into the event
  sensor's grid (bilinear; pixels the frame does not cover are black), so the scene's camera is the event camera
  and ``--intrinsics`` describes it. Frames much larger than the event sensor are first reduced with area
  averaging (no aliasing). Events are never resampled: they keep their exact pixels.
- **Time offset** (``--time-offset-us N``): frame times (sidecar, ``images.txt``, …) are on the frame device's
  clock and t_event = t_frame + N. With ``auto`` the offset is estimated (:func:`estimate_time_offset`).

Estimation (``--time-offset-us auto``): a cross-correlation of the frames' brightness change with the events,
pixel by pixel. For a candidate offset τ and each pair of consecutive frames i, i + 1, every sampled pixel (up to
4096 the frames cover; up to 200 frame pairs) gives its log-brightness change ΔL = ln(Y_{i+1} + ε) − ln(Y_i + ε)
(Y: grey level in [0, 1], ε = 0.02) and its signed event count S over [m_i + τ, m_{i+1} + τ) (m: exposure
midpoints on the frame clock), plus half the polarity of its last event (the level an event leaves is on average
half a threshold behind the brightness). An event is a log-brightness step of one threshold, so ΔL ∝ S at the
true offset: r(τ) is the Pearson correlation of ΔL and S pooled over pixels and pairs. It decorrelates as soon as
the texture moves by about a pixel, so its peak is sharp.

1. **Scan** every offset at which at least half the frame pairs (and at least four) lie inside the recorded
   events (or ``auto:LO,HI``), on a grid of an eighth of the frame period.
2. **Refine** the :data:`CANDIDATES` best local maxima (two periods apart) within ± one period on a grid of
   1/200 of the exposure, with a parabola through the best value and its neighbours; the best one wins.

Cost: (search range / frame period) × 8 offsets × pairs × pixels; on long recordings give ``auto:LO,HI`` when
the offset is roughly known. On the simulated pair (tests/ingest/test_two_clock.py) the estimate lands 0.6–1 ms late
(the sensor's threshold quantisation is not fully modelled), well inside a tenth of its 20 ms exposure.

Confidence, both in the summary:

- ``peak_ratio`` = the winner's correlation / the best correlation of the other candidates
  (at least two frame periods away). Near 1: another offset explains the data almost as well (periodic motion,
  too few frames): the estimate is ambiguous; values below :data:`AMBIGUOUS_RATIO` are flagged in the summary.
- ``interval_us``: a bootstrap 90 % interval: the frame pairs are resampled with replacement 200 times and the
  per-pixel peak searched again; the 5th and 95th percentiles of those offsets. Its width is the precision
  given these frames (not the ambiguity between distant peaks, which the ratio covers).

Frames and events must be on the same pixel grid (the homography is applied first); the search needs at least
five frames with strictly increasing times and motion that changes the amount of blur between frames.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError

log = logging.getLogger(__name__)

LOG_EPS = 0.02  # ε in ln(Y + ε), Y in [0, 1]: keeps dark-pixel noise from dominating the brightness change
MIN_PAIRS = 4  # frame pairs needed inside the events at an offset
BOOTSTRAP = 200
AMBIGUOUS_RATIO = 1.5
MAX_EVENT_TIMES = 20_000_000  # event times kept for the estimate (every k-th beyond this; counts scale by k)
SCAN_BLOCK = 64  # offsets scored together in the scan (memory: pixels × block × 8 bytes per frame time)
MAX_REFINE_PAIRS = 200  # frame pairs used by the per-pixel refinement (evenly spaced)
CANDIDATES = 5  # best scan peaks refined


# --- homography ----------------------------------------------------------------------------------------------
def parse_homography(path: str | Path) -> np.ndarray:
    """A 3×3 frame→event homography from a text file (9 numbers, row-major, whitespace or commas, ``#`` comments)
    or a ``.npy`` (3, 3) array → (3, 3) float64 normalised to H[2, 2] = 1 (when non-zero)."""
    from eigs.ingest.options import read_number_file

    p = Path(path)
    if not p.is_file():
        raise EigsError(p, "no such homography file")
    if p.suffix == ".npy":
        try:
            H = np.load(p, allow_pickle=False)
        except Exception as err:
            raise EigsError(p, f"not a readable .npy array ({type(err).__name__})") from None
        H = np.asarray(H, np.float64)
        if H.shape != (3, 3):
            raise EigsError(p, f"homography has shape {H.shape}, expected (3, 3)")
    else:
        values = read_number_file(p)
        if len(values) != 9:
            raise EigsError(p, f"a homography needs 9 numbers (3×3, row-major), found {len(values)}")
        H = np.asarray(values, np.float64).reshape(3, 3)
    if not np.all(np.isfinite(H)):
        raise EigsError(p, "homography contains NaN/Inf")
    if abs(H[2, 2]) > 1e-12:
        H = H / H[2, 2]
    if abs(np.linalg.det(H)) < 1e-12 * max(1.0, float(np.abs(H).max()) ** 3):
        raise EigsError(p, "homography is singular (determinant 0)")
    return H


def warp_frames(frames: np.ndarray, H: np.ndarray, width: int, height: int) -> tuple[np.ndarray, float]:
    """Frames (M, h, w, C) uint8 in the frame camera's grid → (M, ``height``, ``width``, C) uint8 in the event
    sensor's grid, with x_event ~ H x_frame (OpenCV pixel coordinates). Returns the frames and the fraction of
    event pixels the frames cover. Frames shrunk by more than 1.5× are first area-averaged to the target scale."""
    import cv2

    M, h, w, C = frames.shape
    H = np.asarray(H, np.float64)
    # local scale of the map at the frame centre (√|det| of its Jacobian)
    c = np.array([(w - 1) / 2, (h - 1) / 2, 1.0])
    q = H @ c
    J = (H[:2, :2] * q[2] - np.outer(q[:2], H[2, :2])) / q[2] ** 2
    scale = float(np.sqrt(abs(np.linalg.det(J))))
    src = frames
    if scale < 1 / 1.5:
        nw, nh = max(1, round(w * scale)), max(1, round(h * scale))
        sx, sy = nw / w, nh / h
        src = np.stack([_as_hwc(cv2.resize(f, (nw, nh), interpolation=cv2.INTER_AREA), C) for f in frames])
        # resized pixel x' = (x + 0.5)·s − 0.5  ⇒  x = (x' + 0.5)/s − 0.5
        S_inv = np.array([[1 / sx, 0, 0.5 / sx - 0.5], [0, 1 / sy, 0.5 / sy - 0.5], [0, 0, 1]])
        H = H @ S_inv
        h, w = nh, nw
    out = np.empty((M, height, width, C), np.uint8)
    for i, f in enumerate(src):
        out[i] = _as_hwc(
            cv2.warpPerspective(f, H, (width, height), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT), C
        )
    mask = cv2.warpPerspective(np.full((h, w), 255, np.uint8), H, (width, height), flags=cv2.INTER_NEAREST)
    return out, float(np.count_nonzero(mask)) / (width * height)


def _as_hwc(img: np.ndarray, channels: int) -> np.ndarray:
    return img[:, :, None] if img.ndim == 2 and channels == 1 else img


# --- time offset ---------------------------------------------------------------------------------------------
def parse_time_offset(text: str) -> int | tuple[str, tuple[int, int] | None]:
    """``--time-offset-us``: ``N`` (integer µs, t_event = t_frame + N), ``auto`` (search every offset at which
    the frames overlap the events) or ``auto:LO,HI`` (search LO ≤ offset ≤ HI µs) → int or ("auto", range)."""
    s = text.strip()
    if re.fullmatch(r"[+-]?\d+", s):
        return int(s)
    m = re.fullmatch(r"auto(?::\s*([+-]?\d+)\s*,\s*([+-]?\d+))?", s)
    if not m:
        raise EigsError("--time-offset-us", f"expected an integer (µs), auto or auto:LO,HI, got {text!r}")
    if m.group(1) is None:
        return ("auto", None)
    lo, hi = int(m.group(1)), int(m.group(2))
    if hi < lo:
        raise EigsError("--time-offset-us", f"auto:LO,HI needs LO ≤ HI, got {lo},{hi}")
    return ("auto", (lo, hi))


@dataclass
class OffsetEstimate:
    """Result of :func:`estimate_time_offset` (µs on the event clock minus the frame clock)."""

    offset_us: int
    correlation: float  # pooled per-pixel Pearson r between brightness change and signed events at the offset
    second_correlation: float  # per-pixel r of the best other candidate (−1 when there is none)
    peak_ratio: float  # correlation / second_correlation (inf when the latter is ≤ 0)
    interval_us: tuple[int, int]  # bootstrap 90 % interval
    pairs: int  # frame pairs used at the offset
    search_us: tuple[int, int]
    fine_step_us: int

    @property
    def ambiguous(self) -> bool:
        return self.peak_ratio < AMBIGUOUS_RATIO

    def describe(self) -> str:
        ratio = "inf" if not np.isfinite(self.peak_ratio) else f"{self.peak_ratio:.2f}"
        text = (
            f"time offset estimated: {self.offset_us} µs (t_event = t_frame + offset); correlation "
            f"{self.correlation:.3f} "
            f"over {self.pairs} frame pairs, peak ratio {ratio} (best other candidate "
            f"{self.second_correlation:.3f}), bootstrap 90 % interval [{self.interval_us[0]}, "
            f"{self.interval_us[1]}] µs; "
            f"searched [{self.search_us[0]}, {self.search_us[1]}] µs"
        )
        if self.ambiguous:
            text += (
                f"; AMBIGUOUS (peak ratio < {AMBIGUOUS_RATIO}): another offset fits almost as well, check it or give "
                "--time-offset-us N (or auto:LO,HI around the right one)"
            )
        return text


@dataclass
class EventSample:
    """Events gathered for the estimate. ``t``: (N,) int64 sorted times of every ``step``-th event (the span
    searched); ``pixels``: (X,) int64 flat indices y·W + x of the sampled pixels; ``col``: (M,)
    int64 column into ``pixels`` of each event at those pixels, ``t_px``: (M,) int64 its time, ``p_px``: (M,)
    int8 its polarity (all events at the sampled pixels, time-ordered)."""

    t: np.ndarray
    step: int
    pixels: np.ndarray
    col: np.ndarray
    t_px: np.ndarray
    p_px: np.ndarray


def sample_pixels(mask: np.ndarray, n: int = 4096, seed: int = 0) -> np.ndarray:
    """Up to ``n`` flat pixel indices (sorted) drawn from the True pixels of ``mask`` (H, W)."""
    idx = np.flatnonzero(mask.ravel())
    if idx.size > n:
        idx = np.sort(np.random.default_rng(seed).choice(idx, size=n, replace=False))
    return idx.astype(np.int64)


def gather_events(chunks, width: int, height: int, pixels: np.ndarray, n_events: int | None) -> EventSample:
    """One pass over time-ordered chunks (x, y, t, p) → :class:`EventSample` (every event time when there are at
    most :data:`MAX_EVENT_TIMES`, else every k-th; all events at ``pixels``)."""
    step = max(1, -(-(n_events or 0) // MAX_EVENT_TIMES))
    lut = np.full(width * height, -1, np.int64)
    lut[pixels] = np.arange(pixels.shape[0])
    ts, cols, tps, pps = [], [], [], []
    seen = 0
    for x, y, t, p in chunks:
        first = (-seen) % step
        ts.append(t[first::step])
        seen += t.shape[0]
        c = lut[y.astype(np.int64) * width + x.astype(np.int64)]
        keep = c >= 0
        cols.append(c[keep])
        tps.append(t[keep])
        pps.append(p[keep])

    def cat(parts, dt):
        return np.concatenate(parts).astype(dt) if parts else np.zeros(0, dt)

    return EventSample(cat(ts, np.int64), step, pixels, cat(cols, np.int64), cat(tps, np.int64), cat(pps, np.int8))


def _log_grey(frames: np.ndarray) -> np.ndarray:
    """(V, H, W, C) uint8 → (V, H, W) float32 ln(Y + ε)."""
    return np.log(frames.astype(np.float32).mean(axis=-1) / 255.0 + LOG_EPS)


def _pixel_sums(dl: np.ndarray, mid: np.ndarray, ev: EventSample, taus: np.ndarray, pairs: np.ndarray):
    """Per frame pair ``pairs[j]`` (i: frames i, i + 1) and offset ``taus`` (T,), the sums Pearson's r needs
    between the log-brightness change ``dl`` (P, X) of the sampled pixels and their signed event count S over
    [m_i + τ, m_{i+1} + τ): (P, T, 3) float64 holding ΣS, ΣS², Σ dl·S over the pixels."""
    X = ev.pixels.shape[0]
    T = taus.shape[0]
    t0, t1 = int(taus[0]), int(taus[-1])
    fine = int(taus[1] - taus[0]) if T > 1 else 1
    out = np.zeros((pairs.shape[0], T, 3))  # ΣS, ΣS², Σ dl·S

    pol_all = ev.p_px.astype(np.int64)
    state = {"upto": 0, "base": np.zeros(X), "last": np.full(X, -1, np.int64)}

    def cumulative_at(b: int) -> np.ndarray:
        """(X, T): per pixel, the signed event count before b + τ plus half the polarity of the last of those
        events, for every τ: the log-brightness change in thresholds. (The last event leaves the pixel's
        brightness on average half a threshold beyond its level; without that half step the count lags the
        brightness by the time half a threshold takes.) Boundaries must come in increasing order: the counts
        before b + τ_0 are carried from the previous call, so the whole pass reads each event once."""
        lo_i = int(np.searchsorted(ev.t_px, b + t0, side="left"))
        hi_i = int(np.searchsorted(ev.t_px, b + t1, side="left"))
        done = np.arange(state["upto"], lo_i)
        state["base"] += np.bincount(ev.col[done], weights=pol_all[done], minlength=X)
        np.maximum.at(state["last"], ev.col[done], done)
        state["upto"] = lo_i
        seg = np.arange(lo_i, hi_i)
        col = ev.col[seg]
        k = np.minimum((ev.t_px[seg] - (b + t0)) // fine + 1, T)  # the event counts for grid indices ≥ k
        hist = np.zeros((X, T + 1))
        np.add.at(hist, (col, k), pol_all[seg])
        cum = state["base"][:, None] + np.cumsum(hist, axis=1)[:, :T]
        last = np.full((X, T + 1), -1, np.int64)
        last[:, 0] = state["last"]
        np.maximum.at(last, (col, k), seg)
        last = np.maximum.accumulate(last, axis=1)[:, :T]  # index of the last event before b + τ (−1: none)
        return cum + np.where(last >= 0, 0.5 * pol_all[np.maximum(last, 0)], 0.0)

    cache: dict[int, np.ndarray] = {}
    for j, i in enumerate(pairs):
        lo_c = cache.get(int(i))
        if lo_c is None:
            lo_c = cumulative_at(int(mid[i]))
        hi_c = cumulative_at(int(mid[i + 1]))
        cache = {int(i) + 1: hi_c}
        S = hi_c - lo_c  # (X, T)
        out[j, :, 0] = S.sum(0)
        out[j, :, 1] = (S * S).sum(0)
        out[j, :, 2] = dl[j] @ S
    return out


def _pearson_pooled(sums: np.ndarray, dl: np.ndarray) -> np.ndarray:
    """r(τ) pooled over pairs and pixels from per-pair ``sums`` (P, T, 3) and ``dl`` (P, X)."""
    n = dl.size
    s, ss, sd = sums.sum(0).T
    m, mm = dl.sum(), (dl * dl).sum()
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = sd / n - (s / n) * (m / n)
        var_s = ss / n - (s / n) ** 2
        var_d = mm / n - (m / n) ** 2
        return cov / np.sqrt(var_s * var_d)


def _score(ftaus: np.ndarray, flat: np.ndarray, mid: np.ndarray, ev: EventSample):
    """Pooled per-pixel correlation at the offsets ``ftaus`` (uniform grid): (r (T,), per-pair sums, dl, pairs) or
    None when fewer than :data:`MIN_PAIRS` (or half the) frame pairs lie inside the events for every offset."""
    t_first, t_last = int(ev.t[0]), int(ev.t[-1])
    ok = np.flatnonzero((mid[:-1] + ftaus[0] >= t_first) & (mid[1:] + ftaus[-1] <= t_last))
    if ok.size < max(MIN_PAIRS, (mid.shape[0] - 1) // 2) or ev.pixels.size == 0:
        return None
    if ok.size > MAX_REFINE_PAIRS:
        ok = ok[np.linspace(0, ok.size - 1, MAX_REFINE_PAIRS).round().astype(int)]
    dl = (flat[ok + 1] - flat[ok])[:, ev.pixels]  # (P, X)
    sums = _pixel_sums(dl, mid, ev, ftaus, ok)
    return _pearson_pooled(sums, dl), sums, dl, ok


def _refine(center: int, period: float, fine: int, flat: np.ndarray, mid: np.ndarray, ev: EventSample):
    """± one frame period around ``center`` at step ``fine``: (offset µs, sub-step by a parabola through the best
    value and its neighbours; r there; per-pair sums; dl; the offsets; the pairs) or None."""
    ftaus = np.arange(center - int(period), center + int(period) + 1, fine, dtype=np.int64)
    got = _score(ftaus, flat, mid, ev)
    if got is None or not np.any(np.isfinite(got[0])):
        return None
    rf, sums, dl, ok = got
    k = int(np.nanargmax(rf))
    offset = float(ftaus[k])
    if 0 < k < ftaus.shape[0] - 1 and np.all(np.isfinite(rf[k - 1 : k + 2])):
        y0, y1, y2 = rf[k - 1 : k + 2]
        den = y0 - 2 * y1 + y2
        if den < 0:
            offset += fine * float(np.clip(0.5 * (y0 - y2) / den, -0.5, 0.5))
    return int(round(offset)), float(rf[k]), sums, dl, ftaus, ok


def estimate_time_offset(
    frames: np.ndarray,
    mid_us: np.ndarray,
    ev: EventSample,
    *,
    exposure_len_us: float | None = None,
    search_us: tuple[int, int] | None = None,
    seed: int = 0,
    where: str | Path | None = None,
) -> OffsetEstimate:
    """Offset τ (µs) with t_event = t_frame + τ, from the frames' brightness change and the events.

    ``frames``: (V, H, W, C) uint8 in time order **in the event sensor's grid** (after the homography);
    ``mid_us``: (V,) int64 exposure midpoints (or timestamps) on the frame clock, strictly increasing; ``ev``:
    the events (:func:`gather_events`; its ``pixels`` index the frames' H × W grid); ``exposure_len_us``: typical
    exposure, sets the fine step (default: the frame period); ``search_us``: (lo, hi) offsets to search (default:
    every offset at which the frames overlap the events). Raises :class:`EigsError` (naming ``where``) when no
    offset can be scored.

    Scan, then refine the best candidates (module docstring): signed events per pixel against the brightness
    change between frames.
    """
    mid = np.asarray(mid_us, np.int64)
    V = mid.shape[0]
    if V < MIN_PAIRS + 1:
        raise EigsError(where, f"--time-offset-us auto needs at least {MIN_PAIRS + 1} frames, got {V}")
    if np.any(np.diff(mid) <= 0):
        raise EigsError(where, "--time-offset-us auto needs strictly increasing frame times")
    if ev.t.shape[0] < 2 or ev.t[-1] <= ev.t[0]:
        raise EigsError(where, "--time-offset-us auto needs events spanning some time")
    logs = _log_grey(frames)  # (V, H, W)
    flat = logs.reshape(V, -1)
    period = float(np.median(np.diff(mid)))
    exposure = float(exposure_len_us) if exposure_len_us and exposure_len_us > 0 else period
    lo, hi = search_us if search_us is not None else (int(ev.t[0] - mid[-1]), int(ev.t[-1] - mid[0]))
    coarse = max(1, int(period // 8))
    taus = np.arange(lo, hi + 1, coarse, dtype=np.int64)
    r = np.full(taus.shape[0], np.nan)
    for s0 in range(0, taus.shape[0], SCAN_BLOCK):
        got = _score(taus[s0 : s0 + SCAN_BLOCK], flat, mid, ev)
        if got is not None:
            r[s0 : s0 + SCAN_BLOCK] = got[0]
    if not np.any(np.isfinite(r)):
        raise EigsError(
            where,
            f"--time-offset-us auto: no offset in [{lo}, {hi}] µs puts at least half the frame pairs inside the "
            "events with varying brightness (frames and events do not overlap, or nothing moves)",
        )
    r_fill = np.where(np.isfinite(r), r, -np.inf)
    # candidates: the best local maxima of the scan, at least two frame periods apart
    order = np.argsort(-r_fill)
    cands: list[int] = []
    for i in order:
        if not np.isfinite(r_fill[i]) or len(cands) == CANDIDATES:
            break
        is_max = (i == 0 or r_fill[i] >= r_fill[i - 1]) and (i == r.shape[0] - 1 or r_fill[i] >= r_fill[i + 1])
        if is_max and all(abs(int(taus[i]) - int(taus[j])) >= 2 * period for j in cands):
            cands.append(int(i))
    fine = max(1, int(round(exposure / 200)))
    results = [_refine(int(taus[i]), period, fine, flat, mid, ev) for i in cands]
    scored = [(res[1], i, res) for i, res in zip(cands, results, strict=True) if res is not None]
    if not scored:
        raise EigsError(where, "--time-offset-us auto: the sampled pixels have no events or no brightness change, "
                        "or too few frame pairs lie inside the events")  # fmt: skip
    scored.sort(key=lambda x: -x[0])
    pix_r, best, (offset, _, sums, dl, ftaus, ok) = scored[0]
    others = [sc[0] for sc in scored[1:] if abs(int(taus[sc[1]]) - offset) >= 2 * period]
    second = max(others) if others else -1.0
    ratio = pix_r / second if second > 0 else float("inf")
    rng = np.random.default_rng(seed)
    boot = []
    for _ in range(BOOTSTRAP):
        idx = rng.integers(0, ok.size, ok.size)
        rb = _pearson_pooled(sums[idx], dl[idx])
        if np.any(np.isfinite(rb)):
            boot.append(int(ftaus[int(np.nanargmax(rb))]))
    interval = (int(np.percentile(boot, 5)), int(np.percentile(boot, 95))) if boot else (int(offset), int(offset))
    return OffsetEstimate(
        offset_us=int(round(offset)),
        correlation=pix_r,
        second_correlation=second,
        peak_ratio=ratio,
        interval_us=interval,
        pairs=int(ok.size),
        search_us=(int(lo), int(hi)),
        fine_step_us=fine,
    )
