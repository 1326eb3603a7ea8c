"""The COLMAP model SfM writes into ``b{B}/sfm/`` (``cameras.bin``, ``images.bin``, ``points3D.bin``), read with
pycolmap: the one import of pycolmap's (after cv2) and the 3D points the ``init`` stage starts from."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from eigs.errors import EigsError


def load_pycolmap() -> Any:
    """Import pycolmap after cv2: in the other order, using cv2 once pycolmap is loaded aborted the process with
    "double free or corruption" (opencv-contrib 5.0.0.93 + pycolmap 4.2.1)."""
    import cv2  # noqa: F401
    import pycolmap

    return pycolmap


def read_points(sfm: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """The model's 3D points: positions (P, 3) float64 world units of the canonical frame and colours (P, 3)
    float64 in [0, 1]. Raises :class:`EigsError` when ``sfm`` holds no readable model."""
    sfm = Path(sfm)
    if not (sfm / "points3D.bin").is_file():
        raise EigsError(sfm, "no points3D.bin (not an sfm/ output directory; run `eigs sfm` first)")
    pycolmap = load_pycolmap()
    try:
        rec = pycolmap.Reconstruction(str(sfm))
    except Exception as err:  # pycolmap raises RuntimeError/ValueError for broken models
        raise EigsError(sfm, f"cannot read the COLMAP model ({err})") from None
    pts = list(rec.points3D.values())
    xyz = np.array([p.xyz for p in pts], np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in pts], np.float64).reshape(-1, 3) / 255.0
    return xyz, rgb
