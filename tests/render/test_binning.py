"""Tile binning: the parallel sort/count/scatter gives exactly the documented order for any thread count."""

from __future__ import annotations

import math

import pytest
import torch

from eigs.render import _backend


def _reference_bins(means2d, extents, depths, radii, width: int, height: int) -> list[list[int]]:
    """Per tile (row-major), the ids of the Gaussians whose box touches it, by (depth, index)."""
    tx, ty = (width + 15) // 16, (height + 15) // 16
    bins: list[list[int]] = [[] for _ in range(tx * ty)]
    order = sorted((g for g in range(len(depths)) if radii[g][0] > 0), key=lambda g: (depths[g], g))
    for g in order:
        (mx, my), (ex, ey) = means2d[g], extents[g]
        j0, j1 = max(math.ceil(mx - ex - 0.5), 0), min(math.floor(mx + ex - 0.5), width - 1)
        i0, i1 = max(math.ceil(my - ey - 0.5), 0), min(math.floor(my + ey - 0.5), height - 1)
        if j0 > j1 or i0 > i1:
            continue
        for t_y in range(i0 // 16, i1 // 16 + 1):
            for t_x in range(j0 // 16, j1 // 16 + 1):
                bins[t_y * tx + t_x].append(g)
    return bins


@pytest.mark.parametrize("depth_kind", ["ties", "wide"])
@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_binning_order_is_exact_for_any_thread_count(dtype: torch.dtype, depth_kind: str) -> None:
    g = torch.Generator().manual_seed(5)
    # >= 4 x 1024 Gaussians: up to 4 threads really run (3 runs: 2 merge rounds, one with an odd run; every merge
    # is cut into one piece per thread at co-ranks), and every chunk holds >= 256 keys, so the radix sort runs
    n, W, H = 5000, 83, 61
    means2d = (torch.rand(n, 2, generator=g, dtype=torch.float64) * torch.tensor([W + 40.0, H + 40.0]) - 20).to(dtype)
    extents = (0.5 + 12 * torch.rand(n, 2, generator=g, dtype=torch.float64)).to(dtype)
    if depth_kind == "ties":  # few distinct depths: many ties, which must be ordered by index
        depths = (1 + torch.randint(0, 7, (n,), generator=g).to(torch.float64) / 4).to(dtype)
    else:  # log-uniform over 1e-2 .. 1e6 (every radix digit varies), every 50th a repeat of the first
        depths = torch.exp(torch.empty(n, dtype=torch.float64).uniform_(math.log(1e-2), math.log(1e6), generator=g))
        depths[1::50] = depths[0]
        depths = depths.to(dtype)
    radii = extents.ceil().to(torch.int32)
    radii[torch.rand(n, generator=g) < 0.2] = 0  # culled
    ref = _reference_bins(means2d.double().tolist(), extents.double().tolist(), depths.double().tolist(),
                          radii.tolist(), W, H)  # fmt: skip
    want_ids = torch.tensor([i for b in ref for i in b], dtype=torch.int64)
    want_offsets = torch.tensor([0] + [len(b) for b in ref], dtype=torch.int64).cumsum(0)
    C = _backend.load()
    before = torch.get_num_threads()
    try:
        for threads in (1, 2, 3, 4):
            torch.set_num_threads(threads)
            offsets, ids = C.isect_tiles(means2d, extents, depths, radii, W, H)
            assert torch.equal(offsets, want_offsets), threads
            assert torch.equal(ids, want_ids), threads
    finally:
        torch.set_num_threads(before)
