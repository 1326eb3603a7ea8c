"""The CPU pipeline as one autograd Function per op: project -> tile intersect -> rasterize to pixels.

Shapes: N Gaussians, D colour channels, an H x W image, n_isects (Gaussian, tile) pairs, 16 x 16 tiles.
"""

from __future__ import annotations

import os

import torch
from torch import Tensor
from torch.autograd.function import FunctionCtx, once_differentiable

from eigs.render import _backend


def _isa() -> int:
    return _backend.isa_code(os.environ.get("EIGS_RENDER_ISA", "auto"))


class _ProjectGaussians(torch.autograd.Function):
    """means (N,3), quats (N,4), scales (N,3), opacities (N,), colors (N,D) -> means2d (N,2), conics (N,3),
    depths (N,), extents (N,2), radii (N,2) int32. Differentiable in means2d and conics; opacities and colors
    only take part in the culling (a non-finite colour culls its Gaussian); the camera ``cam`` (the 16 viewmat
    and 9 K entries as floats) is a constant."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: FunctionCtx,
        means: Tensor,
        quats: Tensor,
        scales: Tensor,
        opacities: Tensor,
        colors: Tensor,
        cam: list[float],
        width: int,
        height: int,
    ) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
        means2d, conics, depths, extents, radii = _backend.load().project_fwd(
            means, quats, scales, opacities, colors, cam, width, height
        )
        ctx.save_for_backward(means, quats, scales, radii)
        ctx.cam, ctx.width, ctx.height = cam, width, height
        ctx.mark_non_differentiable(depths, extents, radii)
        return means2d, conics, depths, extents, radii

    @staticmethod
    @once_differentiable
    def backward(ctx: FunctionCtx, v_means2d: Tensor, v_conics: Tensor, *_unused: Tensor):  # type: ignore[override]
        means, quats, scales, radii = ctx.saved_tensors
        v_means2d = torch.zeros_like(means[:, :2]) if v_means2d is None else v_means2d.contiguous()
        v_conics = torch.zeros_like(means) if v_conics is None else v_conics.contiguous()
        v_means, v_quats, v_scales = _backend.load().project_bwd(
            means, quats, scales, ctx.cam, ctx.width, ctx.height, radii, v_means2d, v_conics
        )
        return v_means, v_quats, v_scales, None, None, None, None, None


def camera_list(viewmat: Tensor, K: Tensor, dtype: torch.dtype) -> list[float]:
    """The 16 entries of viewmat then the 9 of K (row-major), rounded to ``dtype``, as Python floats."""
    return torch.cat((viewmat.detach().reshape(-1), K.detach().reshape(-1))).to(dtype).tolist()


def project(
    means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor, cam: list[float], width: int,
    height: int,
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Project N Gaussians (see :class:`_ProjectGaussians`). All inputs contiguous, one float dtype."""
    return _ProjectGaussians.apply(means, quats, scales, opacities, colors, cam, width, height)


@torch.no_grad()
def isect_tiles(
    means2d: Tensor, extents: Tensor, depths: Tensor, radii: Tensor, width: int, height: int
) -> tuple[Tensor, Tensor]:
    """Tile binning (not differentiable).

    Returns tile_offsets (n_tiles + 1,) int64 into flatten_ids (n_isects,) int64: per tile in row-major tile
    order, the ids of the Gaussians whose conservative box touches it, in ascending depth (ties by index).
    """
    return _backend.load().isect_tiles(means2d.detach(), extents, depths, radii, width, height)


class _RasterizeToPixels(torch.autograd.Function):
    """means2d (N,2), conics (N,3), colors (N,D), opacities (N,), background (D,) -> image (H,W,D),
    alpha (H,W)."""

    @staticmethod
    def forward(  # type: ignore[override]
        ctx: FunctionCtx,
        means2d: Tensor,
        conics: Tensor,
        colors: Tensor,
        opacities: Tensor,
        background: Tensor,
        extents: Tensor,
        tile_offsets: Tensor,
        flatten_ids: Tensor,
        width: int,
        height: int,
        isa: int,
    ) -> tuple[Tensor, Tensor]:
        image, alpha, trans, last = _backend.load().rasterize_fwd(
            means2d, conics, colors, opacities, extents, background, tile_offsets, flatten_ids, width, height,
            isa,
        )
        ctx.save_for_backward(
            means2d, conics, colors, opacities, background, extents, tile_offsets, flatten_ids, trans, last
        )
        ctx.width, ctx.height, ctx.isa = width, height, isa
        return image, alpha

    @staticmethod
    @once_differentiable
    def backward(ctx: FunctionCtx, v_image: Tensor, v_alpha: Tensor):  # type: ignore[override]
        (means2d, conics, colors, opacities, background, extents, tile_offsets, flatten_ids, trans,
         last) = ctx.saved_tensors  # fmt: skip
        H, W = ctx.height, ctx.width
        D = colors.shape[1]
        v_image = means2d.new_zeros(H, W, D) if v_image is None else v_image.contiguous()
        v_alpha = means2d.new_zeros(H, W) if v_alpha is None else v_alpha.contiguous()
        v_means2d, v_conics, v_opacities, v_colors, v_background = _backend.load().rasterize_bwd(
            means2d, conics, colors, opacities, extents, background, tile_offsets, flatten_ids, W, H, trans,
            last, v_image, v_alpha, ctx.isa,
        )
        return v_means2d, v_conics, v_colors, v_opacities, v_background, None, None, None, None, None, None


def rasterize_to_pixels(
    means2d: Tensor, conics: Tensor, colors: Tensor, opacities: Tensor, background: Tensor, extents: Tensor,
    tile_offsets: Tensor, flatten_ids: Tensor, width: int, height: int, isa: int | None = None,
) -> tuple[Tensor, Tensor]:
    """Composite the binned Gaussians (see :class:`_RasterizeToPixels`); ``isa`` None reads EIGS_RENDER_ISA."""
    return _RasterizeToPixels.apply(
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
    # A non-finite colour culls its Gaussian in the projection (the kernels never read culled colours).
    means2d, conics, depths, extents, radii = project(means, quats, scales, opacities, colors, cam, width, height)
    tile_offsets, flatten_ids = isect_tiles(means2d, extents, depths, radii, width, height)
    image, alpha = rasterize_to_pixels(
        means2d, conics, colors, opacities, background, extents, tile_offsets, flatten_ids, width, height, isa
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
