"""The radiance-field model file (``model.npz`` of a field run folder; docs/training.md "Field runs").

An uncompressed NumPy ``.npz`` archive with:

- ``format`` = ``"eigs-field"``, ``version`` = 2 (0-d arrays; version 1 files are read too);
- ``grid`` (1 + C, Z, Y, X) float32: raw density (channel 0) and raw colour (channels 1..C) at the voxel corners
  of a grid spanning the box [``lo``, ``hi``] (``align_corners`` semantics: corner (0, 0, 0) is at ``lo``,
  corner (X−1, Y−1, Z−1) at ``hi``; x is the last axis), trilinearly interpolated in the warped coordinates;
- ``warp`` (2, 3, K) float64, optional (absent: linear over the box, knots lo, hi → 0, 1): per axis (x, y, z) K
  knots of a piecewise-linear, increasing map from world coordinates (``warp[0, a]``, from ``lo[a]`` to
  ``hi[a]``) to normalised grid coordinates (``warp[1, a]``, from 0 to 1; the corner index is u · (n − 1)): the
  grid's corners are evenly spaced in u, so a segment with a steeper map has finer voxels (a fine core around the
  object, coarser shells out to the walls);
- ``lo``, ``hi`` (3,) float64: the box in the canonical SfM frame (world units);
- ``occupancy`` (Z, Y, X) bool: voxels that may hold density (samples nearest an empty voxel are skipped);
- ``density_shift`` (scalar): density σ = softplus(raw + shift) per world unit; colour = sigmoid(raw colour), pixel
  values in [0, 1] (linear or sRGB as the scene's frames);
- ``n_samples`` (scalar int): samples per ray, evenly spaced between the ray's entry into and exit from the box
  (midpoints at render time); ``near`` (scalar): the nearest distance sampled.

No torch: readable by any NumPy program.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.atomic import atomic_path

FIELD_FORMAT = "eigs-field"
FIELD_VERSION = 2
FIELD_FILE = "model.npz"


@dataclass
class FieldArrays:
    """A radiance field as stored (see the module docstring for units and layout)."""

    grid: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    occupancy: np.ndarray
    density_shift: float
    n_samples: int
    near: float
    warp: np.ndarray | None = None  # (2, 3, K); None: linear over the box (knots lo, hi → 0, 1)

    @property
    def channels(self) -> int:
        return int(self.grid.shape[0]) - 1

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.grid.shape[1:]))

    def validate(self, where: str | os.PathLike) -> None:
        g = self.grid
        if g.ndim != 4 or g.shape[0] < 2 or min(g.shape[1:]) < 2:
            raise EigsError(where, f"grid must be (1 + C, Z, Y, X) with every size >= 2, got {g.shape}")
        if self.occupancy.shape != g.shape[1:] or self.occupancy.dtype != bool:
            raise EigsError(where, f"occupancy must be bool {g.shape[1:]}, got {self.occupancy.dtype} "
                            f"{self.occupancy.shape}")  # fmt: skip
        if self.lo.shape != (3,) or self.hi.shape != (3,) or not np.all(self.hi > self.lo):
            raise EigsError(where, f"box must have lo < hi per axis, got {self.lo} .. {self.hi}")
        if not np.all(np.isfinite(g)):
            raise EigsError(where, "grid has NaN/Inf values")
        if self.n_samples < 1 or not (np.isfinite(self.density_shift) and self.near >= 0):
            raise EigsError(where, "n_samples must be >= 1, density_shift finite, near >= 0")
        if self.warp is not None:
            w = np.asarray(self.warp)
            ok = w.ndim == 3 and w.shape[:2] == (2, 3) and w.shape[2] >= 2 and bool(np.all(np.isfinite(w)))
            ok = ok and bool(np.all(np.diff(w, axis=2) > 0)) and np.allclose(w[0, :, 0], self.lo)
            ok = ok and np.allclose(w[0, :, -1], self.hi) and np.allclose(w[1, :, 0], 0) and np.allclose(w[1, :, -1], 1)
            if not ok:
                raise EigsError(where, "warp must be (2, 3, K) increasing knots from lo..hi to 0..1 per axis")


def write_field(field: FieldArrays, path: str | os.PathLike) -> None:
    """Write ``field`` to ``path`` (``.npz``) atomically."""
    field.validate(path)
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(
            fh,
            format=np.array(FIELD_FORMAT),
            version=np.array(FIELD_VERSION),
            grid=np.ascontiguousarray(field.grid, np.float32),
            lo=np.asarray(field.lo, np.float64),
            hi=np.asarray(field.hi, np.float64),
            occupancy=np.ascontiguousarray(field.occupancy, bool),
            density_shift=np.array(float(field.density_shift)),
            n_samples=np.array(int(field.n_samples)),
            near=np.array(float(field.near)),
            **({} if field.warp is None else {"warp": np.asarray(field.warp, np.float64)}),
        )


def read_field(path: str | os.PathLike) -> FieldArrays:
    """Read and check a field model file; a missing, foreign or broken file raises :class:`EigsError`."""
    path = Path(path)
    if not path.is_file():
        raise EigsError(path, "no such field model file")
    try:
        with np.load(path, allow_pickle=False) as z:
            if str(z["format"]) != FIELD_FORMAT:
                raise EigsError(path, f"not an {FIELD_FORMAT} file (format {z['format']!s})")
            version = int(z["version"])
            if version not in (1, FIELD_VERSION):
                raise EigsError(path, f"field version {version}, this reader knows 1 and {FIELD_VERSION}")
            field = FieldArrays(
                grid=z["grid"].astype(np.float32),
                lo=z["lo"].astype(np.float64),
                hi=z["hi"].astype(np.float64),
                occupancy=z["occupancy"].astype(bool),
                density_shift=float(z["density_shift"]),
                n_samples=int(z["n_samples"]),
                near=float(z["near"]),
                warp=z["warp"].astype(np.float64) if "warp" in z.files else None,
            )
    except EigsError:
        raise
    except (OSError, KeyError, ValueError) as err:
        raise EigsError(path, f"unreadable field model ({err})") from None
    field.validate(path)
    return field
