"""The SfM stage's HDF5 artifacts, read by training and evaluation through this module only.

- ``sfm/poses.h5`` (:class:`LatentPoses`): per training view the B+1 latent camera-to-world poses (OpenCV axes,
  canonical frame), which were registered by SfM, interpolated within their view, or copied (sharp views).
- ``sfm/test_cameras.h5`` (:class:`TestCameras`): one camera per ground-truth sharp image of the scene, in the
  model's (canonical) frame, with how it was obtained and the registration's reprojection error.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from eigs.artifacts._h5 import open_artifact
from eigs.errors import H5_READ_ERRORS, EigsError
from eigs.util.atomic import atomic_path, ensure_space, nbytes_of

POSES_FORMAT = "eigs-sfm-poses"
TEST_FORMAT = "eigs-sfm-test-cameras"
FORMAT_VERSION = 1
MODES = ("colmap", "given", "model")
# how a test camera's pose was obtained
METHOD_REGISTERED = 0  # registered into the frozen model (2-D–3-D matches, absolute pose)
METHOD_FALLBACK = 1  # the ground-truth pose mapped into the model frame by the Sim(3)
METHOD_GIVEN = 2  # given mode: the ground-truth pose in the canonical frame (exact)
METHODS = {METHOD_REGISTERED: "registered", METHOD_FALLBACK: "fallback", METHOD_GIVEN: "given"}


@dataclass
class LatentPoses:
    """Latent camera poses of V training views with L = B + 1 latent times each.

    - ``c2w``: (V, L, 4, 4) float64 camera-to-world, OpenCV axes, canonical frame; NaN where ``valid`` is False.
    - ``timestamps_us``: (V, L) int64 latent times (from EDI).
    - ``registered``: (V, L) bool, the pose comes from SfM (or is given).
    - ``interpolated``: (V, L) bool, filled from registered latents of the same view.
    - ``sharp``: (V,) bool, views EDI marked sharp: one image, its pose copied to every slot.
    - ``K``: (3, 3) intrinsics (pixel centres at j+0.5); ``width``, ``height`` in pixels.
    - ``mode``: ``colmap``, ``given`` or ``model`` (an existing COLMAP model's poses); ``canonical``: (4, 4)
      similarity source → canonical frame.
    """

    c2w: np.ndarray
    timestamps_us: np.ndarray
    registered: np.ndarray
    interpolated: np.ndarray
    sharp: np.ndarray
    K: np.ndarray
    width: int
    height: int
    mode: str
    canonical: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def valid(self) -> np.ndarray:
        """(V, L) bool: poses usable downstream (registered, interpolated, or copied within a sharp view)."""
        return np.all(np.isfinite(self.c2w), axis=(-2, -1))

    @property
    def n_views(self) -> int:
        return int(self.c2w.shape[0])

    @property
    def n_latent(self) -> int:
        return int(self.c2w.shape[1])

    def validate(self, path: str | os.PathLike | None) -> None:
        v, l_ = self.c2w.shape[:2]
        checks = [
            (self.c2w.ndim == 4 and self.c2w.shape[2:] == (4, 4), "c2w must be (V, L, 4, 4)"),
            (self.timestamps_us.shape == (v, l_), "timestamps_us must be (V, L)"),
            (self.registered.shape == (v, l_) and self.registered.dtype == np.bool_, "registered must be (V, L) bool"),
            (
                self.interpolated.shape == (v, l_) and self.interpolated.dtype == np.bool_,
                "interpolated must be (V, L) bool",
            ),
            (self.sharp.shape == (v,) and self.sharp.dtype == np.bool_, "sharp must be (V,) bool"),
            (self.K.shape == (3, 3), "K must be (3, 3)"),
            (self.mode in MODES, f"mode must be one of {MODES}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise EigsError(path, msg)


def write_poses(poses: LatentPoses, path: str | os.PathLike) -> None:
    poses.validate(path)
    ensure_space(path, nbytes_of(poses))
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(
            format=POSES_FORMAT, version=FORMAT_VERSION, mode=poses.mode, width=poses.width, height=poses.height
        )
        for name in ("c2w", "timestamps_us", "registered", "interpolated", "sharp", "K", "canonical"):
            f.create_dataset(name, data=getattr(poses, name))


def _open(path: str | os.PathLike, fmt: str, what: str) -> h5py.File:
    return open_artifact(path, fmt, FORMAT_VERSION, what, "sfm")


def read_poses(path: str | os.PathLike) -> LatentPoses:
    """Read ``sfm/poses.h5`` (or the ``sfm/`` directory holding it)."""
    p = Path(path)
    if p.is_dir():
        p = p / "poses.h5"
    with _open(p, POSES_FORMAT, "SfM poses") as f:
        try:
            poses = LatentPoses(
                c2w=f["c2w"][()],
                timestamps_us=f["timestamps_us"][()],
                registered=f["registered"][()],
                interpolated=f["interpolated"][()],
                sharp=f["sharp"][()],
                K=f["K"][()],
                width=int(f.attrs["width"]),
                height=int(f.attrs["height"]),
                mode=str(f.attrs["mode"]),
                canonical=f["canonical"][()],
            )
        except H5_READ_ERRORS as err:
            raise EigsError(p, f"corrupted SfM poses file ({err})") from None
    poses.validate(p)
    return poses


@dataclass
class TestCameras:
    """Cameras of the S ground-truth sharp images, in the model's (canonical) frame.

    - ``c2w``: (S, 4, 4) float64 camera-to-world, OpenCV axes; ``K``: (S, 3, 3); ``width``, ``height``.
    - ``index``: (S,) int64 row of the image in the scene's ``gt/sharp``; ``kind``: (S,) uint8 (0 blur view,
      1 novel view); ``view``: (S,) int64 training view or −1; ``t_us``: (S,) int64.
    - ``method``: (S,) uint8, see :data:`METHODS`; ``reprojection_error_px``: (S,) float64 mean reprojection
      error of the registration's inliers (NaN when not registered); ``num_inliers``: (S,) int64.
    """

    __test__ = False  # not a pytest test class despite the name

    c2w: np.ndarray
    K: np.ndarray
    width: int
    height: int
    index: np.ndarray
    kind: np.ndarray
    view: np.ndarray
    t_us: np.ndarray
    method: np.ndarray
    reprojection_error_px: np.ndarray
    num_inliers: np.ndarray

    def __len__(self) -> int:
        return int(self.c2w.shape[0])

    def validate(self, path: str | os.PathLike | None) -> None:
        s = len(self)
        if self.c2w.shape != (s, 4, 4) or self.K.shape != (s, 3, 3):
            raise EigsError(path, "test cameras: c2w must be (S, 4, 4) and K (S, 3, 3)")
        for name in ("index", "kind", "view", "t_us", "method", "reprojection_error_px", "num_inliers"):
            if getattr(self, name).shape != (s,):
                raise EigsError(path, f"test cameras: {name} must be (S,)")
        if not np.all(np.isfinite(self.c2w)):
            raise EigsError(path, "test cameras: c2w has NaN/Inf values")


def write_test_cameras(cams: TestCameras, path: str | os.PathLike) -> None:
    cams.validate(path)
    ensure_space(path, nbytes_of(cams))
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs.update(format=TEST_FORMAT, version=FORMAT_VERSION, width=cams.width, height=cams.height)
        f.attrs["methods"] = ",".join(f"{k}={v}" for k, v in METHODS.items())
        for name in ("c2w", "K", "index", "kind", "view", "t_us", "method", "reprojection_error_px", "num_inliers"):
            f.create_dataset(name, data=getattr(cams, name))


def read_test_cameras(path: str | os.PathLike) -> TestCameras:
    """Read ``sfm/test_cameras.h5`` (or the ``sfm/`` directory holding it)."""
    p = Path(path)
    if p.is_dir():
        p = p / "test_cameras.h5"
    with _open(p, TEST_FORMAT, "test cameras") as f:
        try:
            cams = TestCameras(
                c2w=f["c2w"][()],
                K=f["K"][()],
                width=int(f.attrs["width"]),
                height=int(f.attrs["height"]),
                **{
                    n: f[n][()]
                    for n in ("index", "kind", "view", "t_us", "method", "reprojection_error_px", "num_inliers")
                },
            )
        except H5_READ_ERRORS as err:
            raise EigsError(p, f"corrupted test cameras file ({err})") from None
    cams.validate(p)
    return cams
