"""A small hand-built evaluation case: a scene (with or without ground truth), SfM artifacts and a run folder with a
random Gaussian cloud in front of the cameras. No other stage runs, so these tests are fast."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eigs.artifacts.gaussians import GaussianCloud, rgb_to_sh_dc, write_gaussian_ply
from eigs.artifacts.poses import METHOD_GIVEN, LatentPoses, TestCameras, write_poses, write_test_cameras
from eigs.scene import Camera, Frames, Scene, SharpImages, write_scene

W, H, V, L = 48, 40, 3, 5
K = np.array([[40.0, 0.0, W / 2], [0.0, 40.0, H / 2], [0.0, 0.0, 1.0]])


def camera_at(x: float, y: float, z: float = -3.0) -> np.ndarray:
    """Camera-to-world (OpenCV axes) at (x, y, z), looking along +z (towards the origin's plane)."""
    m = np.eye(4)
    m[:3, 3] = [x, y, z]
    return m


def make_case(root: Path, *, ground_truth: bool = True, seed: int = 0, n_gaussians: int = 300) -> dict[str, Path]:
    """Write scene.h5, sfm/{poses,test_cameras}.h5 and run/{model.ply,config.json,train_log.csv} under ``root``."""
    rng = np.random.default_rng(seed)
    scene = Scene(name="evalcase", camera=Camera(K=K, width=W, height=H), channels=3, camera_response="linear",
                  synthetic=True, background=np.zeros(3), source="unit test")  # fmt: skip
    scene.frames = Frames(rng.integers(0, 256, (V, H, W, 3), dtype=np.uint8), None)
    views = np.stack([np.stack([camera_at(0.1 * v + 0.01 * k, 0.05 * v) for k in range(L)]) for v in range(V)])
    tc2w = np.stack([views[0, 0], views[1, 0], camera_at(0.25, -0.1), camera_at(-0.2, 0.1)])
    kind = np.array([0, 0, 1, 1], np.uint8)
    view = np.array([0, 1, -1, -1], np.int64)
    if ground_truth:
        # smooth images with structure (LPIPS and SSIM see something), different from any render
        yy, xx = np.mgrid[0:H, 0:W]
        gt = np.stack([np.stack([128 + 100 * np.sin(xx / (3 + i) + c) * np.cos(yy / (4 + c)) for c in range(3)], -1)
                       for i in range(4)])  # fmt: skip
        scene.sharp = SharpImages(np.clip(gt, 0, 255).astype(np.uint8), tc2w, np.arange(4, dtype=np.int64) * 100,
                                  kind, view)  # fmt: skip
    write_scene(scene, root / "scene.h5")
    sfm = root / "sfm"
    sfm.mkdir(parents=True, exist_ok=True)
    poses = LatentPoses(c2w=views, timestamps_us=np.tile(np.arange(L, dtype=np.int64) * 100, (V, 1)),
                        registered=np.ones((V, L), bool), interpolated=np.zeros((V, L), bool),
                        sharp=np.zeros(V, bool), K=K, width=W, height=H, mode="given")  # fmt: skip
    write_poses(poses, sfm / "poses.h5")
    if ground_truth:
        write_test_cameras(TestCameras(c2w=tc2w, K=np.repeat(K[None], 4, 0), width=W, height=H,
                                       index=np.arange(4, dtype=np.int64), kind=kind, view=view,
                                       t_us=np.arange(4, dtype=np.int64) * 100,
                                       method=np.full(4, METHOD_GIVEN, np.uint8),
                                       reprojection_error_px=np.full(4, np.nan), num_inliers=np.zeros(4, np.int64)),
                           sfm / "test_cameras.h5")  # fmt: skip
    run = root / "run"
    run.mkdir(parents=True, exist_ok=True)
    n = n_gaussians
    cloud = GaussianCloud(
        means=(rng.uniform(-1, 1, (n, 3)) * [0.8, 0.6, 0.5]).astype(np.float32),
        f_dc=rgb_to_sh_dc(rng.uniform(0.1, 0.9, (n, 3))).astype(np.float32),
        f_rest=np.zeros((n, 3, 0), np.float32),
        opacity=np.full(n, 1.0, np.float32),
        log_scales=np.log(rng.uniform(0.03, 0.12, (n, 3))).astype(np.float32),
        quats=np.tile(np.array([1.0, 0, 0, 0], np.float32), (n, 1)),
    )
    write_gaussian_ply(cloud, run / "model.ply")
    cfg = {"train": {"method": "3dgs", "steps": 10, "sh_degree": 0},
           "inputs": {"scene": str(root / "scene.h5"), "edi": str(root / "edi.h5"), "sfm": str(sfm)},
           "run": {"train_seconds": 12.5, "method_options": {}}}  # fmt: skip
    (run / "config.json").write_text(json.dumps(cfg))
    (run / "train_log.csv").write_text("step,wall_s,loss,n_gaussians,psnr_novel,psnr_blur\n5,6.0,0.1,300,10.0,11.0\n"
                                       "10,12.5,0.05,300,12.0,12.5\n")  # fmt: skip
    return {"scene": root / "scene.h5", "sfm": sfm, "run": run}
