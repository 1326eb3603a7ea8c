"""The binning's tile culling: a box's tiles that its ellipse cannot reach are left out, and nothing else changes.

Independent expectations: a brute-force float64 search over every pixel centre of every (Gaussian, tile) pair of the
unculled binning (which pairs can have alpha >= 1/255 at all), and the renders and gradients of the unculled binning,
which the culled one must reproduce bit for bit.
"""

from __future__ import annotations

import math

import pytest
import torch
from render_scenes import random_scene

from eigs.render import _backend
from eigs.render._wrapper import camera_list

ALPHA_MIN = 1.0 / 255.0


def _projected(scene):  # noqa: ANN001, ANN202
    C = _backend.load()
    means, quats, scales, opac, colors, viewmat, K, W, H, bg = scene.args()
    m2, con, dep, ext, radii = C.project_fwd(means, quats, scales, opac, colors, camera_list(viewmat, K, means.dtype),
                                             W, H)  # fmt: skip
    return C, m2, con, dep, ext, radii, opac, colors, bg, W, H


def _pairs(offs: torch.Tensor, ids: torch.Tensor) -> set[tuple[int, int]]:
    """(tile, Gaussian) pairs of a binning."""
    counts = (offs[1:] - offs[:-1]).tolist()
    tiles = [t for t, c in enumerate(counts) for _ in range(c)]
    return set(zip(tiles, ids.tolist(), strict=True))


def _reachable(g: int, tile: int, m2, con, ext, opac, W: int, H: int) -> bool:  # noqa: ANN001
    """Whether some pixel centre of the tile inside g's box has o exp(-sigma) >= 1/255 (float64, every pixel)."""
    tx, ty = tile % ((W + 15) // 16), tile // ((W + 15) // 16)
    (mx, my), (ex, ey) = m2[g].tolist(), ext[g].tolist()
    a, b, c = con[g].tolist()
    o = float(opac[g])
    j0, j1 = max(math.ceil(mx - ex - 0.5), 16 * tx), min(math.floor(mx + ex - 0.5), 16 * tx + 15, W - 1)
    i0, i1 = max(math.ceil(my - ey - 0.5), 16 * ty), min(math.floor(my + ey - 0.5), 16 * ty + 15, H - 1)
    for i in range(i0, i1 + 1):
        for j in range(j0, j1 + 1):
            dx, dy = j + 0.5 - mx, i + 0.5 - my
            sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy
            if sigma >= 0 and o * math.exp(-min(sigma, 30.0)) >= ALPHA_MIN:
                return True
    return False


# small: boxes of 2-24 tiles (culled through tile_geom.h's tile_mask); large: many boxes of over 64 tiles (culled
# row by row from their EllipseRows)
SIZES = {"small": (300, 83, 61, (-5.5, -0.5)), "large": (40, 240, 176, (-3.0, 0.5))}


def _needles(seed: int, dtype: torch.dtype, size: str = "small"):  # noqa: ANN202
    """Scales spread over e^3.5-e^5 per axis (needles, tilted at random) and opacities down to under 1/255."""
    n, W, H, log_scale = SIZES[size]
    return random_scene(n, W, H, seed=seed, opacity=(0.002, 0.99), log_scale=log_scale, dtype=dtype)


@pytest.mark.parametrize(("seed", "size"), [(0, "small"), (1, "small"), (0, "large")])
def test_culled_pairs_are_those_no_pixel_can_reach(seed: int, size: str) -> None:
    C, m2, con, dep, ext, radii, opac, *_ = _projected(_needles(seed, torch.float64, size))
    _, W, H, _ = SIZES[size]
    if size == "large":  # the row-by-row path is exercised
        rect_tiles = [(math.floor((mx + ex - 0.5) / 16) - math.floor((mx - ex) / 16) + 1)
                      * (math.floor((my + ey - 0.5) / 16) - math.floor((my - ey) / 16) + 1)
                      for (mx, my), (ex, ey) in zip(m2.tolist(), ext.tolist(), strict=True)]  # fmt: skip
        assert sum(t > 64 for t in rect_tiles) >= 5
    full = _pairs(*C.isect_tiles(m2, ext, dep, radii, W, H))
    culled = _pairs(*C.isect_tiles(m2, ext, dep, radii, W, H, con, opac))
    assert culled <= full
    dropped = full - culled
    assert len(dropped) > 0.05 * len(full)  # the needles leave out a real share of their boxes' tiles
    for tile, g in sorted(dropped):  # conservative: no dropped pair has a pixel the kernels would composite
        assert not _reachable(g, tile, m2, con, ext, opac, W, H), (tile, g)


@pytest.mark.parametrize("size", ["small", "large"])
@pytest.mark.parametrize("isa", [1, 2, 3])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_culled_binning_renders_and_differentiates_bit_for_bit(dtype: torch.dtype, isa: int, size: str) -> None:
    C, m2, con, dep, ext, radii, opac, colors, bg, W, H = _projected(_needles(2, dtype, size))
    g = torch.Generator().manual_seed(7)
    v_image = torch.randn(H, W, colors.shape[1], generator=g, dtype=torch.float64).to(dtype)
    v_alpha = torch.randn(H, W, generator=g, dtype=torch.float64).to(dtype)
    outs = []
    for cull in (False, True):
        offs, ids = C.isect_tiles(m2, ext, dep, radii, W, H, *((con, opac) if cull else ()))
        image, alpha, trans, last, work = C.rasterize_fwd(m2, con, colors, opac, ext, bg, offs, ids, W, H, isa)
        grads = C.rasterize_bwd(m2, con, colors, opac, ext, bg, offs, ids, W, H, trans, last, work, v_image, v_alpha,
                                isa)  # fmt: skip
        outs.append((ids.numel(), image, alpha, trans, *grads))
    assert outs[1][0] < outs[0][0]
    for a, b in zip(outs[0][1:], outs[1][1:], strict=True):
        assert torch.equal(a, b)


def test_culled_binning_is_the_same_for_any_thread_count() -> None:
    C, m2, con, dep, ext, radii, opac, *_ = _projected(
        random_scene(5000, 200, 150, seed=4, opacity=(0.002, 0.99), log_scale=(-5.5, -1.0))
    )  # >= 4 x 1024 Gaussians: up to 4 binning threads run
    before = torch.get_num_threads()
    try:
        got = []
        for threads in (1, 2, 3, 4):
            torch.set_num_threads(threads)
            got.append(C.isect_tiles(m2, ext, dep, radii, 200, 150, con, opac))
    finally:
        torch.set_num_threads(before)
    for offs, ids in got[1:]:
        assert torch.equal(offs, got[0][0]) and torch.equal(ids, got[0][1])


def test_isect_tiles_needs_conics_and_opacities_together() -> None:
    C, m2, con, dep, ext, radii, opac, *_ = _projected(random_scene(20, 40, 30, seed=5))
    with pytest.raises(RuntimeError, match="together"):
        C.isect_tiles(m2, ext, dep, radii, 40, 30, con, None)
    with pytest.raises(RuntimeError, match="rows"):
        C.isect_tiles(m2, ext, dep, radii, 40, 30, con[:10], opac[:10])
