"""``cameras.npz`` of a run folder: the training cameras as camera refinement left them (``camera_refine: true``).

Written by training for every run that refined its cameras (:mod:`eigs.train.gaussian.camera_refine`); read by
evaluation, which scores both sets against the ground truth (:func:`eigs.metrics.trajectory.trajectory_accuracy`).

- ``before``: (V, 4, 4) float64 each view's reference camera (latent k = 0) as the SfM stage gave it, model frame,
  scene units; NaN rows for views without a valid pose.
- ``after``: (V, 4, 4) float64 the same cameras corrected, ``before · exp(ξ_v)``.
- ``twist``: (V, 6) float64 the corrections ``ξ_v = (ω, ν)``: rotation vector (radians), then translation (scene
  units), in the camera frame; zero for views training never drew.
- ``views``: (V,) bool, the views training drew steps from.
- ``method``: the method name.
"""

from __future__ import annotations

import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.artifacts.run import CAMERAS
from eigs.errors import EigsError
from eigs.util.atomic import atomic_path

CAMERAS_FORMAT = "eigs-refined-cameras"
FORMAT_VERSION = 1


@dataclass
class RefinedCameras:
    """See the module docstring for the fields and their shapes."""

    method: str
    before: np.ndarray
    after: np.ndarray
    twist: np.ndarray
    views: np.ndarray

    def validate(self, path: str | os.PathLike | None) -> None:
        v = self.views.shape[0] if self.views.ndim == 1 else -1
        if self.before.shape != (v, 4, 4) or self.after.shape != (v, 4, 4) or self.twist.shape != (v, 6):
            shapes = f"{self.before.shape}, {self.after.shape}, {self.twist.shape}"
            raise EigsError(path, f"refined cameras: before and after must be (V, 4, 4) and twist (V, 6) for "
                            f"V = {v} views, got {shapes}")  # fmt: skip
        used = self.views.astype(bool)
        for name in ("before", "after", "twist"):
            if not np.all(np.isfinite(getattr(self, name)[used])):
                raise EigsError(path, f"refined cameras: {name} has NaN/Inf values in a trained view")


def write_refined_cameras(cameras: RefinedCameras, path: str | os.PathLike) -> None:
    cameras.validate(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            format=np.array(CAMERAS_FORMAT),
            version=np.array(FORMAT_VERSION),
            method=np.array(cameras.method),
            before=cameras.before.astype(np.float64),
            after=cameras.after.astype(np.float64),
            twist=cameras.twist.astype(np.float64),
            views=cameras.views.astype(bool),
        )


def read_refined_cameras(path: str | os.PathLike) -> RefinedCameras:
    """Read a run's ``cameras.npz`` (or the run folder holding it)."""
    p = Path(path)
    if p.is_dir():
        p = p / CAMERAS
    try:
        with np.load(p, allow_pickle=False) as z:
            if str(z["format"]) != CAMERAS_FORMAT or int(z["version"]) != FORMAT_VERSION:
                raise EigsError(p, f"not a {CAMERAS_FORMAT} v{FORMAT_VERSION} file")
            cameras = RefinedCameras(method=str(z["method"]), before=z["before"], after=z["after"],
                                     twist=z["twist"], views=z["views"])  # fmt: skip
    except FileNotFoundError:
        raise EigsError(p, "no refined-cameras file") from None
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
        raise EigsError(p, f"unreadable refined-cameras file ({err})") from None
    cameras.validate(p)
    return cameras
