"""Scene and EDI files rendered by the test ray caster (independent of eigs.synth and eigs.edi)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eigs.artifacts.edi import EdiResult, latent_png_name, write_edi
from eigs.scene import write_scene
from eigs.scene.model import Camera, Frames, Poses, Scene, SharpImages

from . import raycast as rc


def shake(c2w: np.ndarray, k: int, L: int, amp: float, rng: np.random.Generator, direction: np.ndarray) -> np.ndarray:
    """Latent pose k of L: a small translation along ``direction`` plus a small rotation (intra-exposure motion)."""
    from scipy.spatial.transform import Rotation

    f = k / (L - 1)
    out = c2w.copy()
    out[:3, 3] = c2w[:3, 3] + amp * f * direction
    out[:3, :3] = c2w[:3, :3] @ Rotation.from_rotvec(f * np.radians(1.0) * np.array([0, 1, 0])).as_matrix()
    return out


def make_scene(
    tmp: Path,
    *,
    views: int = 8,
    bins: int = 2,
    width: int = 128,
    height: int = 96,
    novel: int = 3,
    source: str = "ground-truth",
    amp: float = 0.08,
    sharp_views: tuple[int, ...] = (),
    write_latent_pngs: bool = True,
) -> dict:
    """Write ``tmp/scene.h5``, ``tmp/b{bins}/edi.h5`` and the latent PNGs; return paths and ground truth."""
    import cv2

    rng = np.random.default_rng(0)
    L = bins + 1
    K = rc.intrinsics(width, height)
    base = rc.orbit(views)
    latent = np.zeros((views, L, 4, 4))
    for v in range(views):
        d = np.cross(base[v, :3, 2], [0, 0, 1.0])
        d /= np.linalg.norm(d)
        for k in range(L):
            latent[v, k] = base[v] if v in sharp_views else shake(base[v], k, L, amp, rng, d)
    t = (np.arange(views)[:, None] * 100_000 + np.arange(L)[None, :] * (20_000 // bins)).astype(np.int64)
    frames = np.stack([[rc.render(latent[v, k], K, width, height) for k in range(L)] for v in range(views)])
    blurry = frames.astype(np.float64).mean(1).round().astype(np.uint8)
    novel_c2w = rc.orbit(novel, start_deg=0.0, arc_deg=80.0, height=1.4) if novel else np.zeros((0, 4, 4))
    sharp_c2w = np.concatenate([latent[:, 0], novel_c2w])
    sharp_img = np.concatenate(
        [frames[:, 0], *([np.stack([rc.render(c, K, width, height) for c in novel_c2w])] if novel else [])]
    )
    scene = Scene(
        name="raycast",
        camera=Camera(K=K, width=width, height=height),
        channels=3,
        camera_response="linear",
        synthetic=True,
        frames=Frames(blurry=blurry, exposure_us=np.stack([t[:, 0], t[:, -1] + 1], 1)),
        poses=Poses(latent_c2w=latent, latent_t_us=t, source=source),
        sharp=SharpImages(
            images=sharp_img,
            c2w=sharp_c2w,
            t_us=np.concatenate([t[:, 0], np.full(novel, -1, np.int64)]),
            kind=np.concatenate([np.zeros(views, np.uint8), np.ones(novel, np.uint8)]),
            view=np.concatenate([np.arange(views), np.full(novel, -1)]).astype(np.int64),
        ),
    )
    tmp.mkdir(parents=True, exist_ok=True)
    write_scene(scene, tmp / "scene.h5")
    bdir = tmp / f"b{bins}"
    sharp = np.zeros(views, bool)
    sharp[list(sharp_views)] = True
    edi = EdiResult(
        latent=frames.astype(np.float32) / 255.0,
        timestamps_us=t,
        cum_counts=np.zeros((views, L, height, width), np.int32),
        threshold=np.full(views, 0.2),
        sharp=sharp,
        event_count=np.zeros(views, np.int64),
        events_per_pixel=np.zeros(views),
        blur_extent_px=np.zeros(views),
        mode="estimated",
        threshold_scope="scene",
        scene_name="raycast",
    )
    bdir.mkdir(parents=True, exist_ok=True)
    write_edi(edi, bdir / "edi.h5")
    if write_latent_pngs:
        (bdir / "latent").mkdir(exist_ok=True)
        for v in range(views):
            for k in range(L):
                cv2.imwrite(str(bdir / "latent" / latent_png_name(v, k)), cv2.cvtColor(frames[v, k], cv2.COLOR_RGB2BGR))
    return {"scene": tmp / "scene.h5", "edi": bdir / "edi.h5", "latent": latent, "sharp_c2w": sharp_c2w, "dir": bdir}
