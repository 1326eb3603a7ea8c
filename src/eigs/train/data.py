"""Everything a training run reads, loaded once into tensors: the scene's blurry frames, the EDI artifact, the
latent poses, the held-out cameras with their ground truth, the initial Gaussians.

The reference camera of a blurry view is its latent pose k = 0, the pose at which E²NeRF-style ground truth of a
blur view is rendered (``docs/training.md``). Views whose reference pose SfM could not give are left out of every
method that needs it; latent frames whose pose is invalid are left out of the methods that render them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import Tensor

from eigs.artifacts.edi import EdiResult, read_edi
from eigs.artifacts.gaussians import GaussianCloud, read_gaussian_ply
from eigs.artifacts.poses import LatentPoses, read_poses, read_test_cameras
from eigs.errors import EigsError
from eigs.scene import SHARP_KIND_BLUR_VIEW, Scene, read_scene

log = logging.getLogger(__name__)


@dataclass
class HeldOut:
    """Held-out cameras with ground truth: ``c2w`` (S, 4, 4) float64, ``K`` (S, 3, 3), ``images`` (S, H, W, C)
    float32 in [0, 1], ``kind`` (S,) 0 = blur view, 1 = novel view."""

    c2w: Tensor
    K: Tensor
    images: Tensor
    kind: np.ndarray

    def __len__(self) -> int:
        return int(self.c2w.shape[0])


@dataclass
class TrainData:
    """A run's inputs. V views, L = B + 1 latent times, H × W pixels, C channels.

    - ``K`` (3, 3) float32 (the SfM model's intrinsics); ``width``, ``height``; ``channels``; ``background`` (C,).
    - ``blurry`` (V, H, W, C) float32 in [0, 1]; ``latent`` (V, L, H, W, C) float32 EDI latent frames.
    - ``c2w`` (V, L, 4, 4) float64 latent poses (NaN where invalid); ``valid`` (V, L) bool.
    - ``edi``: the EDI artifact (event counts, thresholds, mask) for event losses.
    - ``sharp_train`` (V, H, W, C) float32 ground truth of the blur views at their reference pose, or None;
      ``has_sharp_train`` (V,) bool.
    - ``held_out``: cameras with ground truth for the time-versus-quality log (None when the scene has none).
    - ``camera_response``: ``linear``, ``srgb`` or ``unknown`` (pixel values of the frames).
    """

    scene: Scene
    K: Tensor
    width: int
    height: int
    channels: int
    background: Tensor
    blurry: Tensor
    latent: Tensor
    c2w: Tensor
    valid: np.ndarray
    edi: EdiResult
    poses: LatentPoses
    sharp_train: Tensor | None
    has_sharp_train: np.ndarray
    held_out: HeldOut | None
    init: GaussianCloud
    camera_response: str

    @property
    def n_views(self) -> int:
        return int(self.blurry.shape[0])

    @property
    def n_latent(self) -> int:
        return int(self.c2w.shape[1])

    def reference_views(self) -> np.ndarray:
        """Views whose reference pose (k = 0) is valid."""
        return np.nonzero(self.valid[:, 0])[0]


def _to_float(images: np.ndarray) -> Tensor:
    return torch.from_numpy(np.ascontiguousarray(images)).to(torch.float32) / 255.0


def load_train_data(
    scene_path: str | Path, edi_path: str | Path, sfm_dir: str | Path, init_path: str | Path
) -> TrainData:
    """Load and cross-check a run's inputs; inconsistent artifacts raise :class:`EigsError` naming the file."""
    scene = read_scene(scene_path, events=False)
    scene.require("frames", path=str(scene_path), hint="training needs the blurry frames")
    edi = read_edi(edi_path)
    poses = read_poses(sfm_dir)
    init = read_gaussian_ply(init_path)
    cam = scene.camera
    v = scene.n_views
    blurry = scene.frames.blurry  # type: ignore[union-attr]
    if edi.n_views != v:
        raise EigsError(edi_path, f"EDI has {edi.n_views} views, the scene {v}")
    if poses.n_views != v or poses.n_latent != edi.n_bins + 1:
        raise EigsError(
            sfm_dir, f"poses are (V={poses.n_views}, L={poses.n_latent}), EDI (V={v}, L={edi.n_bins + 1})"
        )
    if edi.latent.shape[2:4] != (cam.height, cam.width) or (poses.width, poses.height) != (cam.width, cam.height):
        raise EigsError(edi_path, "image size differs between the scene, the EDI artifact and the poses")
    if len(init) == 0:
        raise EigsError(init_path, "the initial point cloud has no Gaussians")
    c = int(scene.channels)
    bg = scene.background if scene.background is not None else np.zeros(c)
    valid = poses.valid
    if not valid[:, 0].any():
        raise EigsError(sfm_dir, "no training view has a valid reference pose (latent k = 0)")
    n_skip = int((~valid[:, 0]).sum())
    if n_skip:
        log.warning("%d of %d views have no reference pose and are left out", n_skip, v)

    sharp_train = None
    has_sharp = np.zeros(v, bool)
    held = None
    if scene.sharp is not None:
        s = scene.sharp
        blur_rows = np.nonzero((s.kind == SHARP_KIND_BLUR_VIEW) & (s.view >= 0) & (s.view < v))[0]
        if blur_rows.size:
            st = np.zeros((v, cam.height, cam.width, c), np.uint8)
            st[s.view[blur_rows]] = s.images[blur_rows]
            has_sharp[s.view[blur_rows]] = True
            sharp_train = _to_float(st)
        tc_path = Path(sfm_dir) / "test_cameras.h5"
        if tc_path.exists():
            tc = read_test_cameras(tc_path)
            if len(tc):
                held = HeldOut(
                    c2w=torch.from_numpy(tc.c2w),
                    K=torch.from_numpy(tc.K).to(torch.float32),
                    images=_to_float(s.images[tc.index]),
                    kind=np.asarray(tc.kind),
                )
    return TrainData(
        scene=scene,
        K=torch.from_numpy(np.asarray(poses.K)).to(torch.float32),
        width=int(cam.width),
        height=int(cam.height),
        channels=c,
        background=torch.tensor(np.asarray(bg, np.float32).reshape(c)),
        blurry=_to_float(blurry),
        latent=torch.from_numpy(edi.latent),
        c2w=torch.from_numpy(poses.c2w),
        valid=valid,
        edi=edi,
        poses=poses,
        sharp_train=sharp_train,
        has_sharp_train=has_sharp,
        held_out=held,
        init=init,
        camera_response=scene.camera_response,
    )
