"""The radiance-field model file (``model.npz`` of a field run folder; docs/training.md "Field runs").

An uncompressed NumPy ``.npz`` archive with:

- ``format`` = ``"eigs-field"``, ``version`` = 3 (0-d arrays; versions 1 and 2 are read too);
- ``grid`` (1 + C, Z, Y, X) float32: raw density (channel 0) and raw colour (channels 1..C) at the voxel corners
  of a grid spanning the box [``lo``, ``hi``] (``align_corners`` semantics: corner (0, 0, 0) is at ``lo``,
  corner (X−1, Y−1, Z−1) at ``hi``; x is the last axis), trilinearly interpolated in the warped coordinates;
- optionally (version 3, a ``grid+vm`` field) TensoRF's vector-matrix factors, float32, whose raw values add to the
  grid's: for m = 0, 1, 2 with (a, b) = (x, y), (x, z), (y, z) and c = z, y, x, ``colour_plane_m`` (Cc, R_b, R_a)
  and ``colour_line_m`` (Cc, R_c), ``basis`` (C, 3·Cc), and optionally ``density_plane_m`` (Cd, R_b, R_a) and
  ``density_line_m`` (Cd, R_c) (our trainer writes none); R_x, R_y, R_z are corner counts per axis with the grid's
  corner semantics (their own, finer than the grid's). At normalised coordinates u: raw colour += ``basis`` · (the
  3·Cc products P_m[k](u_a, u_b) · L_m[k](u_c) of the colour factors, m-major; bilinear / linear interpolation),
  raw density += Σ_m Σ_k of the density factors' products;
- ``warp`` (2, 3, K) float64, optional (absent: linear over the box, knots lo, hi → 0, 1): per axis (x, y, z) K
  knots of a piecewise-linear, increasing map from world coordinates (``warp[0, a]``, from ``lo[a]`` to
  ``hi[a]``) to normalised grid coordinates (``warp[1, a]``, from 0 to 1; the corner index is u · (n − 1)): the
  grid's corners are evenly spaced in u, so a segment with a steeper map has finer voxels (a fine core around the
  object, coarser shells out to the walls);
- ``lo``, ``hi`` (3,) float64: the box in the canonical SfM frame (world units);
- ``occupancy`` (Z, Y, X) bool: voxels that may hold density (samples nearest an empty voxel are skipped);
- ``density_shift`` (scalar), ``density_scale`` (scalar, version 3; absent: 1): density
  σ = scale · softplus(raw + shift) per world unit; colour = sigmoid(raw colour), pixel
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

from eigs.artifacts.run import MODEL_NPZ
from eigs.errors import EigsError
from eigs.util.atomic import atomic_path

FIELD_FORMAT = "eigs-field"
FIELD_VERSION = 3
FIELD_FILE = MODEL_NPZ  # the model file of a field run folder (eigs.artifacts.run)
_VM_KEYS = ("density_plane", "density_line", "colour_plane", "colour_line")


@dataclass
class VMArrays:
    """TensoRF vector-matrix factors as stored: three planes (Ch, R_b, R_a) and three lines (Ch, R_c) each for
    density and colour, and the colour basis (C, 3·Cc)."""

    density_planes: list[np.ndarray]
    density_lines: list[np.ndarray]
    colour_planes: list[np.ndarray]
    colour_lines: list[np.ndarray]
    basis: np.ndarray

    def arrays(self) -> dict[str, np.ndarray]:
        out = {"basis": self.basis}
        for key, group in zip(_VM_KEYS, (self.density_planes, self.density_lines, self.colour_planes,
                                         self.colour_lines), strict=True):  # fmt: skip
            out.update({f"{key}_{m}": a for m, a in enumerate(group)})
        return out

    def validate(self, where: str | os.PathLike) -> None:
        # corner counts (R_x, R_y, R_z) from the lines: line m runs along z, y, x
        if len(self.colour_lines) != 3:
            raise EigsError(where, "colour: three planes and three lines expected")
        dims = {2 - m: int(np.shape(self.colour_lines[m])[-1]) for m in range(3)}
        axes = ((0, 1), (0, 2), (1, 2))
        for name, planes, lines in (("density", self.density_planes, self.density_lines),
                                    ("colour", self.colour_planes, self.colour_lines)):  # fmt: skip
            if name == "density" and not planes and not lines:
                continue  # colour factors only
            if len(planes) != 3 or len(lines) != 3:
                raise EigsError(where, f"{name}: three planes and three lines expected")
            ch = planes[0].shape[0] if planes[0].ndim == 3 else -1
            for m, (a, b) in enumerate(axes):
                if planes[m].shape != (ch, dims[b], dims[a]) or lines[m].shape != (ch, dims[2 - m]) or ch < 1:
                    raise EigsError(where, f"{name} factor {m}: plane {planes[m].shape} / line {lines[m].shape} do "
                                    f"not match corner counts {dims} with {ch} channels")  # fmt: skip
        if min(dims.values()) < 2:
            raise EigsError(where, f"VM corner counts must be >= 2, got {dims}")
        if self.basis.ndim != 2 or self.basis.shape[1] != 3 * self.colour_planes[0].shape[0] or self.basis.shape[0] < 1:
            raise EigsError(where, f"basis must be (C, 3·Cc), got {self.basis.shape}")
        if not all(np.all(np.isfinite(a)) for a in self.arrays().values()):
            raise EigsError(where, "VM factors have NaN/Inf values")


@dataclass
class FieldArrays:
    """A radiance field as stored (see the module docstring for units and layout): the grid, plus VM factors whose raw
    values add to the grid's when ``vm`` is set."""

    grid: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    occupancy: np.ndarray
    density_shift: float
    n_samples: int
    near: float
    warp: np.ndarray | None = None  # (2, 3, K); None: linear over the box (knots lo, hi → 0, 1)
    vm: VMArrays | None = None
    density_scale: float = 1.0

    @property
    def channels(self) -> int:
        return int(self.grid.shape[0]) - 1

    @property
    def n_voxels(self) -> int:
        return int(np.prod(self.grid.shape[1:]))

    def validate(self, where: str | os.PathLike) -> None:
        if self.vm is not None:
            self.vm.validate(where)
            if self.vm.basis.shape[0] != self.grid.shape[0] - 1:
                raise EigsError(where, f"VM basis has {self.vm.basis.shape[0]} channels, the grid "
                                f"{self.grid.shape[0] - 1}")  # fmt: skip
        g = self.grid
        if g.ndim != 4 or g.shape[0] < 2 or min(g.shape[1:]) < 2:
            raise EigsError(where, f"grid must be (1 + C, Z, Y, X) with every size >= 2, got {g.shape}")
        if self.occupancy.shape != g.shape[1:] or self.occupancy.dtype != bool:
            raise EigsError(where, f"occupancy must be bool {g.shape[1:]}, got {self.occupancy.dtype} "
                            f"{self.occupancy.shape}")  # fmt: skip
        if not np.all(np.isfinite(g)):
            raise EigsError(where, "grid has NaN/Inf values")
        if self.lo.shape != (3,) or self.hi.shape != (3,) or not np.all(self.hi > self.lo):
            raise EigsError(where, f"box must have lo < hi per axis, got {self.lo} .. {self.hi}")
        if self.n_samples < 1 or not (np.isfinite(self.density_shift) and self.near >= 0):
            raise EigsError(where, "n_samples must be >= 1, density_shift finite, near >= 0")
        if not (np.isfinite(self.density_scale) and self.density_scale > 0):
            raise EigsError(where, f"density_scale must be finite and > 0, got {self.density_scale}")
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
            **({} if field.vm is None else
               {k: np.ascontiguousarray(a, np.float32) for k, a in field.vm.arrays().items()}),  # fmt: skip
            lo=np.asarray(field.lo, np.float64),
            hi=np.asarray(field.hi, np.float64),
            occupancy=np.ascontiguousarray(field.occupancy, bool),
            density_shift=np.array(float(field.density_shift)),
            density_scale=np.array(float(field.density_scale)),
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
            if version not in (1, 2, FIELD_VERSION):
                raise EigsError(path, f"field version {version}, this reader knows 1 to {FIELD_VERSION}")
            vm = None
            if "basis" in z.files:
                vm = VMArrays(*[[z[f"{k}_{m}"].astype(np.float32) for m in range(3) if f"{k}_{m}" in z.files]
                                for k in _VM_KEYS], basis=z["basis"].astype(np.float32))  # fmt: skip
            field = FieldArrays(
                grid=z["grid"].astype(np.float32),
                lo=z["lo"].astype(np.float64),
                hi=z["hi"].astype(np.float64),
                occupancy=z["occupancy"].astype(bool),
                density_shift=float(z["density_shift"]),
                n_samples=int(z["n_samples"]),
                near=float(z["near"]),
                warp=z["warp"].astype(np.float64) if "warp" in z.files else None,
                vm=vm,
                density_scale=float(z["density_scale"]) if "density_scale" in z.files else 1.0,
            )
    except EigsError:
        raise
    except (OSError, KeyError, ValueError) as err:
        raise EigsError(path, f"unreadable field model ({err})") from None
    field.validate(path)
    return field
