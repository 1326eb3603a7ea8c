"""Small fixtures written by the tests in each source format, with the values they encode (the expectations).

Every writer here follows the format's own documentation, independently of :mod:`eigs.ingest`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image

W, H = 11, 7  # non-square and odd, so transposed or flipped axes cannot pass


def random_rotation(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) rotations (QR of Gaussian matrices, det +1)."""
    q, r = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    q = q * np.sign(np.diagonal(r, axis1=1, axis2=2))[:, None, :]
    q[np.linalg.det(q) < 0, :, 0] *= -1
    return q


def random_c2w(rng: np.random.Generator, n: int) -> np.ndarray:
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = random_rotation(rng, n)
    m[:, :3, 3] = rng.normal(size=(n, 3)) * 3
    m[:, 3, 3] = 1
    return m


def save_png(path: Path, a: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    mode = {1: "L", 3: "RGB", 4: "RGBA"}[a.shape[2]]
    Image.fromarray(a[:, :, 0] if a.shape[2] == 1 else a, mode).save(path)


# --- E²NeRF synthetic -------------------------------------------------------------------------------------------
@dataclass
class E2NerfSynthetic:
    folder: Path
    angle_x: float
    train_rgb: np.ndarray  # (V, H, W, 3)
    train_mats: np.ndarray  # (V, 18, 4, 4) Blender c2w of the train frames r_0, r_2, ...
    test_rgba: np.ndarray  # (2V, H, W, 4)
    test_mats: np.ndarray  # (2V, 18, 4, 4)
    counts: np.ndarray  # (V, 4, H, W) signed counts


def write_e2nerf_synthetic(folder: Path, n_views: int = 3, seed: int = 0) -> E2NerfSynthetic:
    """Layout of E²NeRF ``data/synthetic/<scene>``: transform_{train,test}.json with 18 matrices per frame (train JSON
    lists r_0..r_{2V-1}; images exist for even ones), RGBA PNGs (train alpha 255), events.pt float64 (V, 4, H·W)."""
    import torch

    rng = np.random.default_rng(seed)
    angle = 0.69111120
    train_rgb = rng.integers(0, 256, (n_views, H, W, 3), dtype=np.uint8)
    all_mats = random_c2w(rng, 2 * n_views * 18).reshape(2 * n_views, 18, 4, 4)
    frames = [{"file_path": f"./train/r_{k}", "transform_matrix": all_mats[k].tolist()} for k in range(2 * n_views)]
    (folder / "train").mkdir(parents=True)
    (folder / "transform_train.json").write_text(json.dumps({"camera_angle_x": angle, "frames": frames}))
    for v in range(n_views):
        rgba = np.concatenate([train_rgb[v], np.full((H, W, 1), 255, np.uint8)], axis=2)
        save_png(folder / "train" / f"r_{2 * v}.png", rgba)
    test_rgba = rng.integers(0, 256, (2 * n_views, H, W, 4), dtype=np.uint8)
    test_mats = random_c2w(rng, 2 * n_views * 18).reshape(2 * n_views, 18, 4, 4)
    test_mats[::2, 1] = all_mats[::2, 1]  # blur-view GT is rendered at the view's first latent pose
    tframes = [{"file_path": f"./test/r_{k}", "transform_matrix": test_mats[k].tolist()} for k in range(2 * n_views)]
    (folder / "transform_test.json").write_text(json.dumps({"camera_angle_x": angle, "frames": tframes}))
    for k in range(2 * n_views):
        save_png(folder / "test" / f"r_{k}.png", test_rgba[k])
    counts = rng.integers(-3, 4, (n_views, 4, H, W)).astype(np.int32)
    ev = np.zeros((n_views, 4, H * W), dtype=np.float64)  # E²NeRF: np.zeros + ev[view, bin, y * W + x] += ±1
    for v in range(n_views):
        for b in range(4):
            ev[v, b] = counts[v, b].reshape(-1)
    torch.save(torch.from_numpy(ev), folder / "events.pt")
    return E2NerfSynthetic(folder, angle, train_rgb, all_mats[::2], test_rgba, test_mats, counts)


# --- E²NeRF real (LLFF) ------------------------------------------------------------------------------------------
@dataclass
class E2NerfReal:
    folder: Path
    focal: float
    c2w_cv: np.ndarray  # (V, 5, 4, 4) OpenCV c2w encoded in poses_bounds.npy
    images: list[Path]
    counts: np.ndarray  # (V, 4, H, W)


def write_e2nerf_real(folder: Path, n_views: int = 2, seed: int = 1, event_name: str = "events.pt") -> E2NerfReal:
    """Layout of E²NeRF ``data/real-world/<scene>``: images/{5i:03d}.jpg, poses_bounds.npy (5 rows per view, LLFF
    3×5 [down, right, back | t | h w f] + near/far), events.pt (V, 4, H·W) float64."""
    import torch

    rng = np.random.default_rng(seed)
    focal = 9.75
    c2w = random_c2w(rng, 5 * n_views)
    rows = np.zeros((5 * n_views, 17))
    for i, m in enumerate(c2w):
        r = m[:3, :3]
        llff = np.stack([r[:, 1], r[:, 0], -r[:, 2], m[:3, 3], [H, W, focal]], axis=1)  # 3×5
        rows[i, :15] = llff.reshape(-1)
        rows[i, 15:] = [0.5, 20.0]
    folder.mkdir(parents=True, exist_ok=True)
    np.save(folder / "poses_bounds.npy", rows)
    paths = []
    for v in range(n_views):
        p = folder / "images" / f"{5 * v:03d}.jpg"
        p.parent.mkdir(exist_ok=True)
        Image.fromarray(rng.integers(0, 256, (H, W, 3), dtype=np.uint8)).save(p, quality=95)
        paths.append(p)
    counts = rng.integers(-2, 3, (n_views, 4, H, W)).astype(np.int32)
    torch.save(torch.from_numpy(counts.reshape(n_views, 4, H * W).astype(np.float64)), folder / event_name)
    return E2NerfReal(folder, focal, c2w.reshape(n_views, 5, 4, 4), paths, counts)


# --- raw events --------------------------------------------------------------------------------------------------
@dataclass
class RawEvents:
    x: np.ndarray
    y: np.ndarray
    t_us: np.ndarray  # int64 µs
    p01: np.ndarray  # uint8 {0, 1}


def random_events(
    n: int, seed: int = 2, t0: int = 1_000, width: int = W, height: int = H, rate_us: int = 7
) -> RawEvents:
    rng = np.random.default_rng(seed)
    t = t0 + np.cumsum(rng.integers(0, rate_us, n)).astype(np.int64)
    return RawEvents(
        rng.integers(0, width, n).astype(np.uint16),
        rng.integers(0, height, n).astype(np.uint16),
        t,
        rng.integers(0, 2, n).astype(np.uint8),
    )


def write_frames(folder: Path, n: int, seed: int = 3, channels: int = 1) -> tuple[np.ndarray, list[str]]:
    """n PNG frames under folder/images → ((n, H, W, C) pixels, relative paths)."""
    rng = np.random.default_rng(seed)
    px = rng.integers(0, 256, (n, H, W, channels), dtype=np.uint8)
    names = []
    for i in range(n):
        name = f"images/frame_{i:08d}.png"
        save_png(folder / name, px[i])
        names.append(name)
    return px, names


def write_dsec_h5(path: Path, ev: RawEvents, t_offset: int = 0, compress: bool = True, size: bool = True) -> None:
    """DSEC layout: events/{x,y,t,p} (uint16, uint16, uint32 relative µs, uint8), t_offset, ms_to_idx."""
    import h5py
    import hdf5plugin

    t_rel = ev.t_us - t_offset
    kw = {"compression": hdf5plugin.Blosc(cname="zstd", clevel=5, shuffle=hdf5plugin.Blosc.SHUFFLE)} if compress else {}
    with h5py.File(path, "w") as f:
        f.create_dataset("events/x", data=ev.x, chunks=True, **kw)
        f.create_dataset("events/y", data=ev.y, chunks=True, **kw)
        f.create_dataset("events/t", data=t_rel.astype(np.uint32), chunks=True, **kw)
        f.create_dataset("events/p", data=ev.p01, chunks=True, **kw)
        ms = np.arange(int(t_rel[-1]) // 1000 + 1) * 1000
        f.create_dataset("ms_to_idx", data=np.searchsorted(t_rel, ms, side="left").astype(np.uint64))
        f.create_dataset("t_offset", data=np.int64(t_offset))
        if size:
            f.attrs["width"], f.attrs["height"] = W, H


def write_text_events(path: Path, ev: RawEvents, header: list[str] | None = None, fmt: str = "{:.9f}") -> None:
    """ECD/v2e text: ``t x y p`` with t in seconds."""
    lines = list(header or [])
    for t, x, y, p in zip(ev.t_us.tolist(), ev.x.tolist(), ev.y.tolist(), ev.p01.tolist(), strict=True):
        lines.append(f"{fmt.format(t / 1e6)} {x} {y} {p}")
    path.write_text("\n".join(lines) + "\n")
