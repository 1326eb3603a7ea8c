"""A simulated beam-splitter pair: an event camera and a frame camera behind one lens, with separate clocks.

The world is a textured plane at depth ``DEPTH`` seen by a camera translating parallel to it (a pan), so the
event sensor's image at time t is the texture shifted by the camera's position: I_e(x, t) = T(x + p(t)) with
p(t) = f·c(t)/DEPTH (c: camera centre, x right / y down). The frame camera sees the same light through the
homography ``H`` (frame pixels → event pixels): I_f(x_f, t) = I_e(H x_f, t). Both are rendered directly from
the texture (no warp of one into the other), the events by the project's simulator on the event images, the
blurry frames as the mean of linear sub-frames over each exposure. Frame times are written on the frame clock,
t_frame = t_event − ``offset_us``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

EW, EH = 48, 36  # event sensor
FW, FH = 64, 48  # frame camera
FOCAL = 40.0  # event camera focal length (px)
DEPTH = 4.0  # plane depth (scene units)
# frame → event: scale 0.75, a 4° rotation and a shift (OpenCV pixel coordinates)
_A = np.deg2rad(4.0)
H_FE = np.array(
    [[0.75 * np.cos(_A), -0.75 * np.sin(_A), 1.5], [0.75 * np.sin(_A), 0.75 * np.cos(_A), -0.8], [1e-4, -5e-5, 1.0]]
)


@dataclass
class Pair:
    folder: Path
    h5: Path
    sidecar: Path
    homography: Path
    trajectory: Path  # ground-truth T_world_cam text file ('t tx ty tz qx qy qz qw', event clock, seconds)
    offset_us: int
    exposure_us: tuple[int, int]  # (length, period)
    mid_event_us: np.ndarray  # (V,) exposure midpoints on the event clock
    sharp_event_grid: np.ndarray  # (V, EH, EW) float32 linear event-grid images at the midpoints
    blurry_event_grid: np.ndarray  # (V, EH, EW) uint8 blurry frames rendered directly in the event grid
    names: list[str]
    c2w_mid: np.ndarray  # (V, 4, 4) camera-to-world at the exposure midpoints


def _texture(rng: np.random.Generator, size: int = 600) -> np.ndarray:
    import cv2

    t = np.zeros((size, size), np.float32)
    for sigma, amp in ((12.0, 0.5), (4.0, 0.35), (1.5, 0.15)):
        t += amp * cv2.GaussianBlur(rng.uniform(0, 1, (size, size)).astype(np.float32), (0, 0), sigma)
    t = (t - t.min()) / (t.max() - t.min())
    return 0.05 + 0.9 * t


def _sample(tex: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.remap(tex, xs.astype(np.float32), ys.astype(np.float32), cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def pan(t_us: np.ndarray, seed: int) -> np.ndarray:
    """(T, 2) texture offsets (px) of a hand-held-like pan (a few hundred px/s: several px of blur per exposure):
    velocity with a varying amplitude (slow and fast
    stretches, so the amount of motion changes from frame to frame)."""
    rng = np.random.default_rng(seed + 100)
    ts = np.asarray(t_us, np.float64) / 1e6
    out = np.zeros((ts.shape[0], 2))
    for axis in range(2):
        for f, a in ((0.7, 300.0), (1.9, 125.0), (4.3, 50.0), (7.1, 25.0)):
            ph = rng.uniform(0, 2 * np.pi)
            out[:, axis] += a / (2 * np.pi * f) * np.sin(2 * np.pi * f * ts + ph) * (1 + 0.6 * np.sin(2.1 * ts + axis))
    return out + 300.0


def make_pair(
    folder: Path, *, n_frames: int = 60, exposure_us: int = 10_000, period_us: int = 12_500, offset_us: int = 123_457,
    seed: int = 0, dt_us: int = 250,
) -> Pair:  # fmt: skip
    """Write the pair under ``folder``: ``events.h5`` (flat layout, µs), ``events.frames.txt`` (frame clock),
    ``images/``, ``H.txt`` (frame → event), ``groundtruth.txt``. Returns what the tests compare against."""
    import h5py

    from eigs.synth.simulator import SensorParams, simulate
    from tests.ingest.fixtures import save_png

    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    tex = _texture(rng)
    t0 = 20_000
    t_end = t0 + n_frames * period_us + 20_000
    ts = np.arange(0, t_end + dt_us, dt_us, dtype=np.int64)
    p = pan(ts, seed)
    ex, ey = np.meshgrid(np.arange(EW, dtype=np.float64), np.arange(EH, dtype=np.float64))
    ev_imgs = np.stack([_sample(tex, ex + p[i, 0], ey + p[i, 1]) for i in range(ts.shape[0])])  # (T, EH, EW)
    events, _ = simulate(np.log(ev_imgs + 1e-3), ts, SensorParams(contrast_threshold=0.15, threshold_sigma=0.0,
                                                                   refractory_us=0.0), rng)  # fmt: skip
    # frame-camera pixel grid mapped into event pixels
    fx, fy = np.meshgrid(np.arange(FW, dtype=np.float64), np.arange(FH, dtype=np.float64))
    q = H_FE @ np.stack([fx.ravel(), fy.ravel(), np.ones(fx.size)])
    qx, qy = (q[0] / q[2]).reshape(FH, FW), (q[1] / q[2]).reshape(FH, FW)

    starts = t0 + period_us * np.arange(n_frames, dtype=np.int64)
    names, blurry_e, sharp_e, mids = [], [], [], []
    lines = ["# exposure_start_us exposure_end_us image   (frame clock)"]
    for v, s in enumerate(starts):
        sel = np.flatnonzero((ts >= s) & (ts <= s + exposure_us))
        frame = np.mean([_sample(tex, qx + p[i, 0], qy + p[i, 1]) for i in sel], axis=0)
        blurry_e.append(np.floor(np.mean(ev_imgs[sel], axis=0) * 255 + 0.5).astype(np.uint8))
        mid = int(s + exposure_us // 2)
        mids.append(mid)
        pm = pan(np.array([mid]), seed)[0]
        sharp_e.append(_sample(tex, ex + pm[0], ey + pm[1]))
        name = f"images/frame_{v:06d}.png"
        save_png(folder / name, np.floor(frame * 255 + 0.5).astype(np.uint8)[:, :, None])
        names.append(name)
        lines.append(f"{s - offset_us} {s + exposure_us - offset_us} {name}")
    sidecar = folder / "events.frames.txt"
    sidecar.write_text("\n".join(lines) + "\n")
    h5 = folder / "events.h5"
    with h5py.File(h5, "w") as f:
        for k in ("x", "y", "t", "p"):
            f.create_dataset(k, data=getattr(events, k))
        f["t"].attrs["unit"] = "us"
        f.attrs["width"], f.attrs["height"] = EW, EH
    hpath = folder / "H.txt"
    hpath.write_text("# frame pixels -> event pixels\n" + "\n".join(" ".join(f"{v:.12g}" for v in row) for row in H_FE))
    # camera centre: texture offset p = f·c/DEPTH  ⇒  c = p·DEPTH/f (x right, y down), looking along +z
    c = p * DEPTH / FOCAL
    gt = folder / "groundtruth.txt"
    gt.write_text("".join(f"{t / 1e6:.6f} {cx:.9f} {cy:.9f} 0 0 0 0 1\n" for t, (cx, cy) in zip(ts, c, strict=True)))
    mids_a = np.asarray(mids, np.int64)
    pm = pan(mids_a, seed) * DEPTH / FOCAL
    c2w = np.tile(np.eye(4), (n_frames, 1, 1))
    c2w[:, 0, 3], c2w[:, 1, 3] = pm[:, 0], pm[:, 1]
    return Pair(folder, h5, sidecar, hpath, gt, offset_us, (exposure_us, period_us), mids_a, np.stack(sharp_e),
                np.stack(blurry_e), names, c2w)  # fmt: skip
