"""A tiny in-memory scene with every artifact a training run reads (no workflow run): a ring of cameras around a
cloud of Gaussians whose renders are the training frames. ``scale`` multiplies every length (camera centres,
Gaussian positions and sizes): the rendered frames do not depend on it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from eigs.artifacts.edi import EdiResult
from eigs.artifacts.gaussians import GaussianCloud, logit, rgb_to_sh_dc
from eigs.artifacts.poses import METHOD_GIVEN, LatentPoses, TestCameras
from eigs.scene import Camera, Frames, Scene, SharpImages
from eigs.train.data import HeldOut, TrainData

W, H, V, L = 24, 16, 4, 3
K = np.array([[22.0, 0.0, 12.0], [0.0, 22.0, 8.0], [0.0, 0.0, 1.0]])


def look_at(centre: np.ndarray, target: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) camera-to-world in OpenCV axes (z forward, y down) at ``centre`` looking at ``target``."""
    z = (np.zeros(3) if target is None else target) - centre
    z = z / np.linalg.norm(z)
    x = np.cross(z, np.array([0.0, 0.0, 1.0]))
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, centre
    return m


def cloud(n: int, seed: int, scale: float = 1.0) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    return GaussianCloud(
        means=(rng.normal(0.0, 0.35, (n, 3)) * scale).astype(np.float32),
        f_dc=rgb_to_sh_dc(rng.uniform(0.1, 0.9, (n, 3))).astype(np.float32),
        f_rest=np.zeros((n, 3, 0), np.float32),
        opacity=logit(rng.uniform(0.3, 0.9, n)).astype(np.float32),
        log_scales=np.log(rng.uniform(0.04, 0.12, (n, 3)) * scale).astype(np.float32),
        quats=rng.normal(size=(n, 4)).astype(np.float32),
    )


def c2w_ring(scale: float = 1.0) -> np.ndarray:
    """(V, L, 4, 4): V cameras on a ring of radius 3·scale, each with L slightly moved latent poses."""
    out = np.empty((V, L, 4, 4))
    for v in range(V):
        for k in range(L):
            a = 2 * np.pi * v / V + 0.02 * k
            out[v, k] = look_at(scale * np.array([3.0 * np.cos(a), 3.0 * np.sin(a), 0.8 + 0.01 * k]))
    return out


def render_frames(truth: GaussianCloud, c2w: np.ndarray) -> np.ndarray:
    """uint8 (N, H, W, 3) renders of ``truth`` at ``c2w`` (N, 4, 4) on a black background."""
    from eigs.train.gaussian.model import GaussianModel

    model = GaussianModel.from_cloud(truth, 0, 3, torch.device("cpu"))
    imgs = []
    with torch.no_grad():
        for m in c2w:
            img, _, _ = model.render(torch.from_numpy(m), torch.from_numpy(K).float(), W, H, torch.zeros(3), 0)
            imgs.append(np.floor(img.clamp(0, 1).numpy() * 255 + 0.5).astype(np.uint8))
    return np.stack(imgs)


def artifacts(scale: float = 1.0, seed: int = 0) -> dict:
    """Every artifact of a run's inputs (objects, not files): scene, edi, poses, test cameras, init cloud."""
    truth = cloud(80, seed, scale)
    c2w = c2w_ring(scale)
    frames = render_frames(truth, c2w[:, 0])
    latent = np.repeat(frames[:, None].astype(np.float32) / 255.0, L, axis=1)
    novel = np.stack([look_at(scale * np.array([2.5, -1.5, 1.5])), look_at(scale * np.array([-2.0, 2.5, -0.5]))])
    sharp = render_frames(truth, novel)
    scene = Scene(
        name="stress-toy",
        camera=Camera(K=K.copy(), width=W, height=H),
        channels=3,
        camera_response="linear",
        synthetic=True,
        background=np.zeros(3),
        frames=Frames(frames, np.array([[1000 * v, 1000 * v + 500] for v in range(V)], np.int64)),
        sharp=SharpImages(sharp, novel, np.array([0, 1], np.int64), np.ones(2, np.uint8), -np.ones(2, np.int64)),
    )
    times = np.array([[1000 * v, 1000 * v + 250, 1000 * v + 500] for v in range(V)], np.int64)
    edi = EdiResult(
        latent=latent,
        timestamps_us=times,
        cum_counts=np.zeros((V, L, H, W), np.int32),
        threshold=np.full(V, 0.2),
        sharp=np.zeros(V, bool),
        event_count=np.zeros(V, np.int64),
        events_per_pixel=np.zeros(V),
        blur_extent_px=np.zeros(V),
        mode="estimated",
        threshold_scope="given",
        scene_name="stress-toy",
    )
    poses = LatentPoses(
        c2w=c2w,
        timestamps_us=times,
        registered=np.ones((V, L), bool),
        interpolated=np.zeros((V, L), bool),
        sharp=np.zeros(V, bool),
        K=K.copy(),
        width=W,
        height=H,
        mode="given",
    )
    tests = TestCameras(
        c2w=novel,
        K=np.stack([K, K]),
        width=W,
        height=H,
        index=np.arange(2, dtype=np.int64),
        kind=np.ones(2, np.uint8),
        view=-np.ones(2, np.int64),
        t_us=np.zeros(2, np.int64),
        method=np.full(2, METHOD_GIVEN, np.uint8),
        reprojection_error_px=np.full(2, np.nan),
        num_inliers=np.zeros(2, np.int64),
    )
    init = cloud(60, seed + 1, scale)
    return {"scene": scene, "edi": edi, "poses": poses, "tests": tests, "init": init}


def train_data(scale: float = 1.0, seed: int = 0) -> TrainData:
    """The :class:`TrainData` of :func:`artifacts`, built in memory as ``load_train_data`` builds it from files."""
    a = artifacts(scale, seed)
    scene, edi, poses, tests = a["scene"], a["edi"], a["poses"], a["tests"]
    to_f = lambda u8: torch.from_numpy(u8).to(torch.float32) / 255.0  # noqa: E731
    return TrainData(
        scene=scene,
        K=torch.from_numpy(K).to(torch.float32),
        width=W,
        height=H,
        channels=3,
        background=torch.zeros(3),
        blurry=to_f(scene.frames.blurry),
        latent=torch.from_numpy(edi.latent),
        c2w=torch.from_numpy(poses.c2w),
        valid=poses.valid,
        edi=edi,
        poses=poses,
        sharp_train=None,
        has_sharp_train=np.zeros(V, bool),
        held_out=HeldOut(
            torch.from_numpy(tests.c2w), torch.from_numpy(tests.K).float(), to_f(scene.sharp.images), tests.kind
        ),
        init=a["init"],
        camera_response="linear",
    )


def write_all(root: Path, scale: float = 1.0) -> dict[str, Path]:
    """Write every artifact under ``root``; returns name → path (scene.h5, edi.h5, poses.h5, test_cameras.h5,
    init.ply)."""
    from eigs.artifacts.edi import write_edi
    from eigs.artifacts.gaussians import write_gaussian_ply
    from eigs.artifacts.poses import write_poses, write_test_cameras
    from eigs.scene import write_scene

    a = artifacts(scale)
    sfm = root / "sfm"
    paths = {
        "scene": root / "scene.h5",
        "edi": root / "edi.h5",
        "poses": sfm / "poses.h5",
        "tests": sfm / "test_cameras.h5",
        "init": root / "init.ply",
    }
    write_scene(a["scene"], paths["scene"])
    write_edi(a["edi"], paths["edi"])
    write_poses(a["poses"], paths["poses"])
    write_test_cameras(a["tests"], paths["tests"])
    write_gaussian_ply(a["init"], paths["init"])
    return paths
