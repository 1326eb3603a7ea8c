"""The CPU pipeline, one autograd Function per op: project -> tile intersect -> rasterize to pixels.

The Functions are C++ (csrc/autograd.cpp: a forward + backward runs no Python frame); this module is their
Python face. Shapes: N Gaussians, D colour channels, an H x W image, n_isects (Gaussian, tile) pairs, 16 x 16
tiles.
"""

from __future__ import annotations

import os

import torch
from torch import Tensor

from eigs.render import _backend


def _isa() -> int:
    return _backend.isa_code(os.environ.get("EIGS_RENDER_ISA", "auto"))


def camera_list(viewmat: Tensor, K: Tensor, dtype: torch.dtype) -> list[float]:
    """The 16 entries of viewmat then the 9 of K (row-major), rounded to ``dtype``, as Python floats.

    Two ``.tolist()`` calls: cheaper than any chain of small tensor ops (this runs once per render).
    """
    vm, k = viewmat.detach().to(dtype).tolist(), K.detach().to(dtype).tolist()
    return vm[0] + vm[1] + vm[2] + vm[3] + k[0] + k[1] + k[2]


def project(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, cam: list[float], width: int,
    height: int,
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Project N Gaussians (differentiable in means2d and conics).

    means (N,3), quats (N,4), scales (N,3), opacities (N,), colors (N,D) -> means2d (N,2) px, conics (N,3),
    depths (N,), extents (N,2) px, radii (N,2) int32. Opacities and colors only take part in the culling (a
    non-finite colour culls its Gaussian); ``cam`` is :func:`camera_list` (a constant). All inputs contiguous,
    one float dtype.
    """
    return _backend.load().project(means, quats, scales, opacities, colors, cam, width, height)


def isect_tiles(
    means2d: Tensor, extents: Tensor, depths: Tensor, radii: Tensor, width: int, height: int,
    conics: Tensor | None = None, opacities: Tensor | None = None,
) -> tuple[Tensor, Tensor]:
    """Tile binning (not differentiable).

    Returns tile_offsets (n_tiles + 1,) int64 into flatten_ids (n_isects,) int64: per tile in row-major tile
    order, the ids of the Gaussians whose conservative box touches it, in ascending depth (ties by index). With
    ``conics`` (N,3) and ``opacities`` (N,), the tiles of a box that its ellipse cannot reach with alpha ≥ 1/255 are
    left out (the tile culling of docs/rasterizer.md; the pipeline's own binning); the renders are the same.
    """
    return _backend.load().isect_tiles(means2d, extents, depths, radii, width, height, conics, opacities)


def rasterize_to_pixels(
    means2d: Tensor, conics: Tensor, colors: Tensor, opacities: Tensor, background: Tensor, extents: Tensor,
    tile_offsets: Tensor, flatten_ids: Tensor, width: int, height: int, isa: int | None = None,
) -> tuple[Tensor, Tensor]:
    """Composite the binned Gaussians, differentiably in means2d, conics, colors, opacities and background.

    -> image (H,W,D) = C + T * background, alpha (H,W) = 1 - T. ``isa`` None reads EIGS_RENDER_ISA.
    """
    return _backend.load().rasterize_to_pixels(
        means2d, conics, colors, opacities, background, extents, tile_offsets, flatten_ids, width, height,
        _isa() if isa is None else isa,
    )


def rasterize_cpu(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, viewmat: Tensor, K: Tensor,
    width: int, height: int, background: Tensor, isa: int | None = None, cam: list[float] | None = None,
) -> tuple[Tensor, Tensor, dict]:
    """The full CPU pipeline on validated, contiguous inputs of one float dtype (see eigs.render.rasterize).

    ``cam`` is :func:`camera_list` of viewmat and K when the caller has it already. Few tensor ops per call:
    the colour culling, alpha = 1 - T and the background gradient live in the C++ kernels.
    """
    if cam is None:
        cam = camera_list(viewmat, K, means.dtype)
    # project -> isect_tiles -> rasterize_to_pixels, chained in C++ (no Python frame per op, forward or backward).
    image, alpha, means2d, conics, depths, radii, tile_offsets, flatten_ids = _backend.load().rasterize(
        means, quats, scales, opacities, colors, cam, width, height, background, _isa() if isa is None else isa
    )
    info = {
        "backend": "cpu",
        "means2d": means2d,
        "conics": conics,
        "depths": depths,
        "radii": radii,
        "tile_offsets": tile_offsets,
        "flatten_ids": flatten_ids,
        "n_isects": int(flatten_ids.numel()),
        "width": width,
        "height": height,
    }
    return image, alpha, info
