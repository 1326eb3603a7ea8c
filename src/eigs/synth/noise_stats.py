"""Noise statistics of an event stream, measured the same way on a real recording and on a simulated scene.

"Still" pixels are those whose neighbourhood is flat in the frame: the gradient of ln(I + 0.01) (I: BT.601 luma
in [0, 1], Gaussian-smoothed with σ = 2 px) stays below ``grad_max`` (log units per pixel) over a
``window`` × ``window`` square. Events there are mostly sensor noise (shot noise, leak, hot pixels) even while
the camera moves a little. Reported: the event rate per still pixel (Hz) with its exact Poisson 95 % interval,
the ON fraction there and overall (with Clopper–Pearson 95 % intervals), and hot-pixel candidates (still pixels
with ≥ ``hot_min_events`` events).

    python -m eigs.synth.noise_stats --real ../shared/data/real/davis346_lab --scene results/d346-blocks/sim.h5

prints one JSON object (``real`` and/or ``scene`` entries; the scene's exposures only, frame by frame).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError

GRAD_MAX = 0.01  # log units per pixel
WINDOW = 9  # px
SMOOTH_SIGMA = 2.0  # px
HOT_MIN_EVENTS = 3
LUMA = np.array([0.299, 0.587, 0.114])


def _luma01(frame: np.ndarray) -> np.ndarray:
    """(H, W) or (H, W, C) uint8 → (H, W) float64 BT.601 luma in [0, 1]."""
    f = np.asarray(frame, np.float64) / 255.0
    if f.ndim == 3:
        f = f[..., 0] if f.shape[-1] == 1 else f[..., :3] @ LUMA
    return f


def still_mask(frame: np.ndarray, grad_max: float = GRAD_MAX, window: int = WINDOW) -> np.ndarray:
    """(H, W) bool: pixels whose ``window``² neighbourhood has a log-intensity gradient below ``grad_max``."""
    import cv2

    lum = cv2.GaussianBlur(_luma01(frame).astype(np.float32), (0, 0), SMOOTH_SIGMA)
    log_i = np.log(lum + 0.01)
    g = np.hypot(cv2.Sobel(log_i, cv2.CV_32F, 1, 0, ksize=3), cv2.Sobel(log_i, cv2.CV_32F, 0, 1, ksize=3)) / 8.0
    return cv2.dilate(g, np.ones((window, window), np.uint8)) < grad_max


def poisson_interval(n: int, exposure: float, level: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson rate from ``n`` counts over ``exposure`` (pixel·s)."""
    from scipy.stats import chi2

    a = 1.0 - level
    lo = 0.0 if n == 0 else chi2.ppf(a / 2, 2 * n) / 2
    hi = chi2.ppf(1 - a / 2, 2 * n + 2) / 2
    return float(lo / exposure), float(hi / exposure)


def binomial_interval(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Clopper–Pearson interval of a proportion k/n (NaNs when n = 0)."""
    from scipy.stats import beta

    if n == 0:
        return float("nan"), float("nan")
    a = 1.0 - level
    lo = 0.0 if k == 0 else beta.ppf(a / 2, k, n - k + 1)
    hi = 1.0 if k == n else beta.ppf(1 - a / 2, k + 1, n - k)
    return float(lo), float(hi)


def window_counts(x: np.ndarray, y: np.ndarray, p: np.ndarray, width: int, height: int) -> tuple[np.ndarray, ...]:
    """Per-pixel event and ON counts (H, W) int64 of one time window (p: ±1 or {0, 1})."""
    idx = y.astype(np.int64) * width + x.astype(np.int64)
    n = np.bincount(idx, minlength=width * height).reshape(height, width)
    on = np.bincount(idx, weights=(p > 0).astype(np.float64), minlength=width * height).reshape(height, width)
    return n, on.astype(np.int64)


def summarize(windows: list[tuple[np.ndarray, np.ndarray, np.ndarray, float]]) -> dict[str, Any]:
    """Statistics over windows ``(counts (H, W), on_counts (H, W), still (H, W) bool, duration_s)``."""
    n_still = on_still = n_all = on_all = 0
    px_s = 0.0
    hot = n_px = 0
    for n, on, still, dur in windows:
        n_still += int(n[still].sum())
        on_still += int(on[still].sum())
        n_all += int(n.sum())
        on_all += int(on.sum())
        px_s += float(still.sum()) * dur
        hot += int((n[still] >= HOT_MIN_EVENTS).sum())
        n_px += int(still.sum())
    rate = n_still / px_s if px_s > 0 else float("nan")
    return {
        "still_pixels_fraction": n_px / max(1, sum(w[2].size for w in windows)),
        "still_pixel_seconds": px_s,
        "still_events": n_still,
        "still_rate_hz": rate,
        "still_rate_hz_ci95": poisson_interval(n_still, px_s) if px_s > 0 else None,
        "still_on_fraction": on_still / n_still if n_still else float("nan"),
        "still_on_fraction_ci95": binomial_interval(on_still, n_still),
        "all_events": n_all,
        "all_on_fraction": on_all / n_all if n_all else float("nan"),
        "all_on_fraction_ci95": binomial_interval(on_all, n_all),
        f"hot_candidates_ge{HOT_MIN_EVENTS}": hot,
        "hot_candidate_fraction_of_still": hot / n_px if n_px else float("nan"),
    }


def real_davis346(folder: str | Path, frame_index: int = 1) -> dict[str, Any]:
    """Statistics of ``davis346_lab`` (``derived/events.npz`` + ``derived/frame_{i:02d}.png``): the whole
    recording (0.13 s) as one window, still pixels from frame ``frame_index``."""
    import cv2

    folder = Path(folder)
    npz = folder / "derived" / "events.npz"
    png = folder / "derived" / f"frame_{frame_index:02d}.png"
    if not npz.is_file() or not png.is_file():
        raise EigsError(folder, "expected derived/events.npz and derived/frame_NN.png (davis346_lab)")
    d = np.load(npz)
    t = d["t_us"].astype(np.int64)
    frame = cv2.imread(str(png), cv2.IMREAD_GRAYSCALE)
    h, w = frame.shape
    n, on = window_counts(d["x"], d["y"], d["p"].astype(np.int8), w, h)
    out = summarize([(n, on, still_mask(frame), (t[-1] - t[0] + 1) * 1e-6)])
    out.update({"source": str(folder), "mean_frame_luma": float(_luma01(frame).mean()), "size": [w, h]})
    return out


def scene_noise(path: str | Path) -> dict[str, Any]:
    """Statistics of a scene file's raw events inside its exposures, still pixels from each view's blurry frame
    (as stored: 8-bit; a linear response is assumed for the mean luma)."""
    from eigs.scene import read_scene

    s = read_scene(path)
    s.require("frames", "exposure", "events", path=str(path))
    ev, ex, cam = s.events, s.frames.exposure_us, s.camera
    windows = []
    for v in range(s.n_views):
        lo, hi = (int(i) for i in ev.view_index[v])
        n, on = window_counts(ev.x[lo:hi], ev.y[lo:hi], ev.p[lo:hi], cam.width, cam.height)
        windows.append((n, on, still_mask(s.frames.blurry[v]), (ex[v, 1] - ex[v, 0]) * 1e-6))
    out = summarize(windows)
    out.update({"source": str(path), "mean_frame_luma": float(np.mean([_luma01(f).mean() for f in s.frames.blurry])),
                "size": [cam.width, cam.height], "views": s.n_views})
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", metavar="DIR", help="davis346_lab folder (derived/events.npz, derived/frame_01.png)")
    ap.add_argument("--scene", metavar="scene.h5", action="append", default=[], help="a scene file (repeatable)")
    args = ap.parse_args(argv)
    out: dict[str, Any] = {}
    if args.real:
        out["real"] = real_davis346(args.real)
    for sc in args.scene:
        out[str(sc)] = scene_noise(sc)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
