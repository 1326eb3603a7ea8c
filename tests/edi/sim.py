"""A tiny independent event simulator for the EDI tests: a textured plane translated (and slightly rotated) along a
smooth path during each exposure, rendered with bilinear warps in linear intensity; events are the crossings of
ln(Y + ε) levels spaced C apart, timestamps linear between sub-frames (ESIM style, no noise)."""

from __future__ import annotations

import cv2
import numpy as np

from eigs.scene import Camera, Events, Frames, Scene

EPS = 1e-3


def texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """(H', W', 3) linear RGB in [0, 1], larger than (h, w) so warps stay inside."""
    from skimage import data

    img = data.astronaut() if seed % 2 == 0 else data.coffee()
    img = cv2.resize(img, (w * 2, h * 2), interpolation=cv2.INTER_AREA).astype(np.float64) / 255.0
    return np.where(img <= 0.04045, img / 12.92, ((img + 0.055) / 1.055) ** 2.4)


def render(tex: np.ndarray, h: int, w: int, dx: float, dy: float, ang: float) -> np.ndarray:
    cx, cy = tex.shape[1] / 2, tex.shape[0] / 2
    m = cv2.getRotationMatrix2D((cx, cy), np.degrees(ang), 1.0)
    m[0, 2] += dx - (tex.shape[1] - w) / 2
    m[1, 2] += dy - (tex.shape[0] - h) / 2
    return cv2.warpAffine(tex.astype(np.float32), m, (w, h), flags=cv2.INTER_LINEAR).astype(np.float64)


def luma(img: np.ndarray) -> np.ndarray:
    return img[..., 0] * 0.299 + img[..., 1] * 0.587 + img[..., 2] * 0.114


def simulate_events(logs: np.ndarray, times: np.ndarray, c, ref: np.ndarray, c_off=None):
    """logs: (K, H, W) log intensities at ``times`` (K,) µs; returns (x, y, t, p) sorted and the final ref.
    ``c``: the threshold, a number or an (H, W) map of ON thresholds; ``c_off``: an (H, W) map of OFF thresholds
    (default: ``c``) — per-pixel threshold mismatch."""
    xs, ys, ts, ps = [], [], [], []
    h, w = logs.shape[1:]
    c_on = np.broadcast_to(np.asarray(c, np.float64), (h, w))
    c_off = c_on if c_off is None else np.broadcast_to(np.asarray(c_off, np.float64), (h, w))
    for k in range(1, logs.shape[0]):
        l0, l1 = logs[k - 1], logs[k]
        t0, t1 = float(times[k - 1]), float(times[k])
        for sgn in (1, -1):
            c = c_on if sgn > 0 else c_off
            n = np.floor(sgn * (l1 - ref) / c).astype(np.int64)
            n = np.maximum(n, 0)
            idx = np.flatnonzero(n)
            if idx.size == 0:
                continue
            cnt = n.reshape(-1)[idx]
            pix = np.repeat(idx, cnt)
            j = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt) + 1
            lev = ref.reshape(-1)[pix] + sgn * j * c.reshape(-1)[pix]
            a, b = l0.reshape(-1)[pix], l1.reshape(-1)[pix]
            frac = np.clip((lev - a) / np.where(b != a, b - a, 1.0), 0.0, 1.0)
            ts.append(np.rint(t0 + frac * (t1 - t0)).astype(np.int64))
            ys.append(pix // w)
            xs.append(pix % w)
            ps.append(np.full(pix.shape, sgn, np.int8))
            ref = ref + sgn * n * c
    if not ts:
        z = np.zeros(0, np.int64)
        return z, z, z, z.astype(np.int8), ref
    x, y, t, p = (np.concatenate(a) for a in (xs, ys, ts, ps))
    o = np.argsort(t, kind="stable")
    return x[o], y[o], t[o], p[o], ref


def make_scene(
    n_views: int = 3,
    h: int = 48,
    w: int = 64,
    c: float = 0.2,
    shake_px: float = 8.0,
    bins: int = 4,
    sub: int = 64,
    exposure_us: int = 40_000,
    gap_us: int = 10_000,
    seed: int = 0,
    c_maps: tuple[np.ndarray, np.ndarray] | None = None,
):
    """A camera translating/rotating along a smooth random path over the whole recording; view v is exposed over
    [v·(T + gap), v·(T + gap) + T). Events are simulated continuously (also between exposures).

    ``shake_px``: typical displacement (px) during one exposure; ``c_maps``: optional (ON, OFF) per-pixel
    threshold maps (H, W) instead of ``c`` everywhere. Returns (scene, sharp) with sharp:
    (V, B+1, H, W, 3) linear frames at the latent times of eigs.edi.binning.latent_times."""
    from eigs.edi.binning import latent_times

    rng = np.random.default_rng(seed)
    tex = texture(h, w, seed)
    period = exposure_us + gap_us
    total = n_views * period
    freqs = rng.uniform(0.5, 2.0, size=(3, 3)) / exposure_us  # cycles per µs
    phases = rng.uniform(0, 2 * np.pi, size=(3, 3))
    amps = rng.normal(size=(3, 3)) * np.array([[shake_px], [shake_px], [0.02]]) / (2 * np.pi)

    def pose(tt: float):
        q = (amps * np.sin(2 * np.pi * freqs * tt + phases)).sum(axis=1)
        return q[0], q[1], q[2]

    exposures = np.array([[v * period, v * period + exposure_us] for v in range(n_views)], np.int64)
    step = exposure_us / sub
    times = np.arange(0, total + step / 2, step)
    frames = np.stack([render(tex, h, w, *pose(tt)) for tt in times])
    logs = np.log(luma(frames) + EPS)
    if c_maps is None:
        x, y, t, p, _ = simulate_events(logs, times, c, logs[0].copy())
    else:
        x, y, t, p, _ = simulate_events(logs, times, c_maps[0], logs[0].copy(), c_off=c_maps[1])
    blurry, sharp_all = [], []
    for v in range(n_views):
        s, e = exposures[v]
        i0 = int(round(s / step))
        seg = frames[i0 : i0 + sub + 1]
        wts = np.full(sub + 1, 1.0)
        wts[[0, -1]] = 0.5
        blur = np.tensordot(wts / wts.sum(), seg, axes=1)  # exposure average (trapezoid)
        blurry.append(np.clip(np.rint(blur * 255), 0, 255).astype(np.uint8))
        lt = latent_times(exposures[v : v + 1], bins)[0]
        sharp_all.append(np.stack([render(tex, h, w, *pose(tt)) for tt in lt]))
    vi = np.stack([np.searchsorted(t, exposures[:, 0]), np.searchsorted(t, exposures[:, 1])], 1).astype(np.int64)
    K = np.array([[w, 0, w / 2], [0, w, h / 2], [0, 0, 1.0]])
    scene = Scene(
        name="sim",
        camera=Camera(K=K, width=w, height=h),
        channels=3,
        camera_response="linear",
        synthetic=True,
        contrast_threshold=c,
        frames=Frames(np.stack(blurry), exposures),
        events=Events(x.astype(np.uint16), y.astype(np.uint16), t.astype(np.int64), p.astype(np.int8), vi),
    )
    return scene, np.stack(sharp_all)
