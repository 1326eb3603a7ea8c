"""The field's warp (a finer core, coarser shells): the map against np.interp, the voxel sizes it gives against
their closed form, trilinear interpolation through it against a float64 hand-written reference, the packed
renderer on a warped field against the one-ray reference, and the model file round trip."""

from __future__ import annotations

import numpy as np
import torch

from eigs.artifacts.field import FieldArrays, read_field, write_field
from eigs.render.field import FieldTensors, pixel_rays, query, render_rays, warp_coords
from eigs.render.volume import ray_aabb
from eigs.render.volume_reference import composite_ray
from eigs.train.field.model import core_box, grid_shape, make_warp, warp_np
from eigs.train.field.options import FieldOptions

LO, HI = np.array([-2.0, -1.5, -1.0]), np.array([2.0, 2.5, 0.5])
CORE = (np.array([-0.5, -0.4, -0.8]), np.array([0.7, 0.4, 0.1]))


def _field(warp: np.ndarray | None, shape=(9, 11, 10), c: int = 3, seed: int = 0) -> FieldTensors:
    g = torch.Generator().manual_seed(seed)
    grid = torch.randn((1, 1 + c, *shape), generator=g, dtype=torch.float64) * 2.0
    occ = torch.rand(shape, generator=g) > 0.3
    return FieldTensors(grid, torch.from_numpy(LO), torch.from_numpy(HI), occ, 0.5, 64, 0.05, warp)


def test_warp_is_piecewise_linear_through_its_knots_and_gives_finer_core_voxels():
    ratio = 3.0
    warp, extent = make_warp(LO, HI, CORE, ratio)
    assert warp is not None and warp.shape == (2, 3, 4)
    # the knots map to cumulative lengths in core units: shells count 1/ratio per world unit
    for a in range(3):
        lens = np.array([CORE[0][a] - LO[a], CORE[1][a] - CORE[0][a], HI[a] - CORE[1][a]]) / [ratio, 1, ratio]
        np.testing.assert_allclose(extent[a], lens.sum(), rtol=1e-12)
        np.testing.assert_allclose(warp[1, a], np.concatenate([[0], np.cumsum(lens)]) / lens.sum(), rtol=1e-12)
    rng = np.random.default_rng(0)
    pts = rng.uniform(LO - 0.5, HI + 0.5, size=(500, 3))  # some outside the box: clamped
    f = _field(warp)
    u = warp_coords(f, torch.from_numpy(pts)).numpy()
    ref = np.stack([np.interp(pts[:, a], warp[0, a], warp[1, a]) for a in range(3)], axis=1)
    np.testing.assert_allclose(u, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(warp_np(warp, LO, HI, pts), ref, rtol=0, atol=0)
    # corners evenly spaced in u: in the core their world spacing is the core voxel, in the shells ratio × it
    z, y, x = grid_shape(extent, 200_000)
    for a, n in enumerate((x, y, z)):
        corners = np.interp(np.linspace(0, 1, n), warp[1, a], warp[0, a])
        step = np.diff(corners)
        v = extent[a] / (n - 1)
        mid = (corners[:-1] + corners[1:]) / 2
        inner = (mid > CORE[0][a] + v) & (mid < CORE[1][a] - v)
        outer = (mid < CORE[0][a] - ratio * v) | (mid > CORE[1][a] + ratio * v)
        np.testing.assert_allclose(step[inner], v, rtol=1e-9)
        np.testing.assert_allclose(step[outer], ratio * v, rtol=1e-9)
    # no core: the linear map of the box
    none, ext = make_warp(LO, HI, None, ratio)
    assert none is None and np.allclose(ext, HI - LO)
    lin = warp_coords(_field(None), torch.from_numpy(pts)).numpy()
    np.testing.assert_allclose(lin, np.clip((pts - LO) / (HI - LO), 0, 1), atol=1e-12)


def _trilinear64(grid: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Hand-written trilinear interpolation of ``grid`` (C, Z, Y, X) at corner coordinates ``g`` (N, 3) (x, y, z)."""
    c, nz, ny, nx = grid.shape
    out = np.zeros((g.shape[0], c))
    for i, (gx, gy, gz) in enumerate(g):
        x0, y0, z0 = (min(int(np.floor(v)), n - 2) for v, n in ((gx, nx), (gy, ny), (gz, nz)))
        fx, fy, fz = gx - x0, gy - y0, gz - z0
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    w = (fx if dx else 1 - fx) * (fy if dy else 1 - fy) * (fz if dz else 1 - fz)
                    out[i] += w * grid[:, z0 + dz, y0 + dy, x0 + dx]
    return out


def test_query_through_the_warp_matches_a_float64_trilinear_reference():
    warp, _ = make_warp(LO, HI, CORE, 2.5)
    f = _field(warp)
    rng = np.random.default_rng(1)
    pts = rng.uniform(LO, HI, size=(200, 3))
    pts[:50] = rng.uniform(CORE[0], CORE[1], size=(50, 3))  # many in the core
    got = query(f, torch.from_numpy(pts)).numpy()
    nz, ny, nx = f.grid.shape[2:]
    g = warp_np(warp, LO, HI, pts) * (np.array([nx, ny, nz]) - 1)
    np.testing.assert_allclose(got, _trilinear64(f.grid[0].numpy(), g), rtol=1e-9, atol=1e-9)


def test_packed_rendering_of_a_warped_field_matches_the_reference():
    warp, _ = make_warp(LO, HI, CORE, 3.0)
    f = _field(warp, seed=3)
    f.grid = f.grid.float().clone().requires_grad_(True)
    f.lo, f.hi = f.lo.float(), f.hi.float()
    c2w = torch.eye(4)
    c2w[2, 3] = -4.0
    K = torch.tensor([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    g = torch.Generator().manual_seed(5)
    o, d = pixel_rays(c2w, K, torch.rand(24, generator=g) * 16, torch.rand(24, generator=g) * 12)
    bg = torch.tensor([0.2, 0.4, 0.6])
    rgb, acc = render_rays(f, o, d, bg)
    rgb.sum().backward()
    tn, tf = ray_aabb(o, d, f.lo, f.hi, f.near)
    nz, ny, nx = f.grid.shape[2:]
    grid64 = f.grid.detach()[0].double().numpy()
    occ = f.occupancy.numpy()
    for i in range(o.shape[0]):
        s = f.n_samples
        t = tn[i].double() + (torch.arange(s, dtype=torch.float64) + 0.5) / s * (tf[i] - tn[i]).double()
        pts = (o[i].double() + t[:, None] * d[i].double()).numpy()
        gc = warp_np(warp, LO, HI, pts) * (np.array([nx, ny, nz]) - 1)
        raw = torch.from_numpy(_trilinear64(grid64, gc))
        idx = np.round(gc).astype(int)
        keep = torch.from_numpy(occ[idx[:, 2], idx[:, 1], idx[:, 0]]) & bool(tf[i] > tn[i])
        sig = torch.where(keep, torch.nn.functional.softplus(raw[:, 0] + f.density_shift), 0.0)
        delta = ((tf[i] - tn[i]).double() / s).expand(s)
        ref_rgb, ref_acc = composite_ray(sig, torch.sigmoid(raw[:, 1:]), delta, bg.double())
        torch.testing.assert_close(rgb[i].detach().double(), ref_rgb, rtol=1e-4, atol=2e-5)
        torch.testing.assert_close(acc[i].detach().double(), ref_acc, rtol=1e-4, atol=2e-5)
    assert f.grid.grad is not None and torch.isfinite(f.grid.grad).all() and f.grid.grad.abs().sum() > 0


def test_core_box_holds_the_points_near_the_cameras_centre():
    rng = np.random.default_rng(2)
    near = rng.uniform([-0.3, -0.2, -0.8], [0.3, 0.2, -0.1], size=(400, 3))
    far = rng.uniform([-2.4, -2.4, -0.8], [2.4, 2.4, 0.7], size=(400, 3))
    far = far[np.linalg.norm(far, axis=1) > 1.5]
    o = FieldOptions(core_radius=1.2, core_ratio=3.0, box_quantile=0.0, box_margin=0.0)
    a, b = core_box(np.concatenate([near, far]), LO - 1, HI + 1, o)
    np.testing.assert_allclose(a, near.min(0), atol=1e-12)
    np.testing.assert_allclose(b, near.max(0), atol=1e-12)
    assert core_box(near, LO - 1, HI + 1, FieldOptions(core_ratio=1.0)) is None
    assert core_box(far, LO - 1, HI + 1, o) is None  # no point within the radius


def test_model_file_round_trip_keeps_the_warp(tmp_path):
    warp, _ = make_warp(LO, HI, CORE, 3.0)
    f = _field(warp)
    arr = FieldArrays(f.grid[0].float().numpy(), LO, HI, f.occupancy.numpy(), 0.5, 64, 0.05, warp)
    write_field(arr, tmp_path / "m.npz")
    back = read_field(tmp_path / "m.npz")
    np.testing.assert_array_equal(back.warp, warp)
    arr.warp = None
    write_field(arr, tmp_path / "n.npz")
    assert read_field(tmp_path / "n.npz").warp is None
