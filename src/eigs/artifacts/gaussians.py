"""Standard 3D Gaussian Splatting PLY (the layout of the reference implementation and common viewers).

Per vertex, float32: ``x y z nx ny nz f_dc_0..2 f_rest_0..(3·((d+1)²−1)−1) opacity scale_0..2 rot_0..3``.
``f_dc``: SH degree-0 coefficients, f_dc = (rgb − 0.5) / C0 with C0 = 0.28209479; ``f_rest``: higher SH bands,
stored channel-major (all coefficients of R, then G, then B); ``opacity``: logit; ``scale_*``: log of the
standard deviations (world units); ``rot_*``: unit quaternion w x y z. Normals are written as zeros.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.atomic import atomic_path

SH_C0 = 0.28209479177387814


def rgb_to_sh_dc(rgb: np.ndarray) -> np.ndarray:
    """(N, 3) colours in [0, 1] → (N, 3) SH DC coefficients."""
    return (np.asarray(rgb, np.float64) - 0.5) / SH_C0


def sh_dc_to_rgb(dc: np.ndarray) -> np.ndarray:
    return np.asarray(dc, np.float64) * SH_C0 + 0.5


def logit(p: float | np.ndarray) -> np.ndarray:
    p = np.asarray(p, np.float64)
    return np.log(p / (1.0 - p))


@dataclass
class GaussianCloud:
    """Gaussians as stored on disk. ``means`` (N, 3); ``f_dc`` (N, 3); ``f_rest`` (N, 3, K) with K = (d+1)² − 1
    (channel-major like the PLY); ``opacity`` (N,) logits; ``log_scales`` (N, 3); ``quats`` (N, 4) w x y z."""

    means: np.ndarray
    f_dc: np.ndarray
    f_rest: np.ndarray
    opacity: np.ndarray
    log_scales: np.ndarray
    quats: np.ndarray

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return int(round(np.sqrt(self.f_rest.shape[2] + 1))) - 1

    def sh_coefficients(self, sh_degree: int, channels: int) -> np.ndarray:
        """(N, (sh_degree + 1)², channels) float32 SH coefficients, DC first. ``channels`` 1: the mean of the PLY's
        three (grey models are stored three times); bands the cloud lacks are zero, extra ones are dropped."""
        k = (sh_degree + 1) ** 2 - 1
        dc = self.f_dc.astype(np.float32)  # (N, 3)
        rest = self.f_rest.astype(np.float32)  # (N, 3, K_cloud)
        if channels == 1:
            dc = dc.mean(axis=1, keepdims=True)
            rest = rest.mean(axis=1, keepdims=True)
        sh = np.zeros((len(self), k + 1, channels), np.float32)
        sh[:, 0, :] = dc
        kk = min(k, rest.shape[2])
        sh[:, 1 : kk + 1, :] = np.transpose(rest[:, :, :kk], (0, 2, 1))
        return sh

    def validate(self, path: str | os.PathLike | None = None) -> None:
        n = len(self)
        shapes = {
            "means": (n, 3),
            "f_dc": (n, 3),
            "opacity": (n,),
            "log_scales": (n, 3),
            "quats": (n, 4),
        }
        for name, shape in shapes.items():
            if getattr(self, name).shape != shape:
                raise EigsError(path, f"Gaussian {name} has shape {getattr(self, name).shape}, expected {shape}")
        k = self.f_rest.shape[2] if self.f_rest.ndim == 3 else -1
        if self.f_rest.shape[:2] != (n, 3) or (self.sh_degree + 1) ** 2 - 1 != k:
            raise EigsError(path, f"f_rest has shape {self.f_rest.shape}, expected (N, 3, (d+1)²−1)")
        for name in ("means", "f_dc", "f_rest", "opacity", "log_scales", "quats"):
            if not np.all(np.isfinite(getattr(self, name))):
                raise EigsError(path, f"Gaussian {name} has NaN/Inf values")


def _fields(sh_degree: int) -> list[str]:
    k = 3 * ((sh_degree + 1) ** 2 - 1)
    return (
        ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
        + [f"f_rest_{i}" for i in range(k)]
        + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    )


def write_gaussian_ply(cloud: GaussianCloud, path: str | os.PathLike) -> None:
    """Write a binary little-endian 3DGS PLY atomically."""
    from plyfile import PlyData, PlyElement

    cloud.validate(path)
    n = len(cloud)
    names = _fields(cloud.sh_degree)
    cols = np.concatenate(
        [
            cloud.means,
            np.zeros((n, 3)),
            cloud.f_dc,
            cloud.f_rest.reshape(n, -1),
            cloud.opacity[:, None],
            cloud.log_scales,
            cloud.quats,
        ],
        axis=1,
    ).astype(np.float32)
    arr = np.empty(n, dtype=[(name, "<f4") for name in names])
    for i, name in enumerate(names):
        arr[name] = cols[:, i]
    with atomic_path(path) as tmp:
        PlyData([PlyElement.describe(arr, "vertex")], text=False, byte_order="<").write(str(tmp))


def read_gaussian_ply(path: str | os.PathLike) -> GaussianCloud:
    """Read a 3DGS PLY (any SH degree) into float32 arrays."""
    from plyfile import PlyData

    p = Path(path)
    if not p.exists():
        raise EigsError(p, "no such PLY file")
    try:
        v = PlyData.read(str(p))["vertex"]
    except Exception as err:  # plyfile raises several types for malformed files
        raise EigsError(p, f"not a readable PLY file with a vertex element ({err})") from None
    names = set(v.data.dtype.names)
    need = {"x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2", "rot_0",
            "rot_1", "rot_2", "rot_3"}  # fmt: skip
    if not need <= names:
        raise EigsError(p, f"not a 3DGS PLY: missing properties {sorted(need - names)}")
    rest = [f"f_rest_{i}" for i in range(sum(1 for n in names if n.startswith("f_rest_")))]
    if not set(rest) <= names or len(rest) % 3:
        raise EigsError(p, f"not a 3DGS PLY: {len(rest)} f_rest properties, expected f_rest_0.. in a multiple of 3")
    n = len(v.data)

    def col(name: str) -> np.ndarray:
        return np.asarray(v.data[name], np.float32)

    f_rest = np.stack([col(r) for r in rest], axis=1).reshape(n, 3, -1) if rest else np.zeros((n, 3, 0), np.float32)
    cloud = GaussianCloud(
        means=np.stack([col("x"), col("y"), col("z")], 1),
        f_dc=np.stack([col(f"f_dc_{i}") for i in range(3)], 1),
        f_rest=f_rest,
        opacity=col("opacity"),
        log_scales=np.stack([col(f"scale_{i}") for i in range(3)], 1),
        quats=np.stack([col(f"rot_{i}") for i in range(4)], 1),
    )
    cloud.validate(p)
    return cloud
