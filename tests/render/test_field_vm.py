"""The grid+vm field (a dense grid plus TensoRF vector-matrix factors) and the density scale: the factors' values
against a float64 hand-written bilinear × linear reference (forward and backward), the packed renderer on a grid+vm
field with a density scale against the float64 one-ray reference, the model file round trip (and a version-2 file
without the new keys), growth of the factors (exact on a field linear along each axis), and the trainer's
total-variation gradient of the factors against autograd of the formula."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eigs.artifacts.field import FieldArrays, read_field, write_field
from eigs.errors import EigsError
from eigs.render.field import LINE_AXES, PLANE_AXES, FieldTensors, VMFactors, pixel_rays, render_rays, vm_query
from eigs.render.volume import ray_aabb
from eigs.render.volume_reference import composite_ray
from eigs.train.field.factors import grow_vm, make_vm, vm_arrays, vm_from_leaves, vm_tv_grad_

DIMS = (7, 5, 4)  # R_x, R_y, R_z


def _vm(density: int = 2, colour: int = 3, channels: int = 3, seed: int = 0, dtype=torch.float64) -> VMFactors:
    torch.manual_seed(seed)
    vm = make_vm(DIMS, density, colour, channels, 1.0, torch.device("cpu"))
    return vm_from_leaves([t.detach().to(dtype).requires_grad_(True) for t in vm.leaves()], density=density > 0)


def _lerp(values: np.ndarray, x: float) -> float:
    """Linear interpolation of ``values`` (n,) at x ∈ [0, 1] over corners 0..n−1 (align_corners)."""
    p = x * (len(values) - 1)
    i = min(int(np.floor(p)), len(values) - 2)
    f = p - i
    return (1 - f) * values[i] + f * values[i + 1]


def _reference(vm: VMFactors, u: np.ndarray) -> np.ndarray:
    """(N, 1 + C) by the formula, point by point, in float64 NumPy."""
    dp = [p.detach().double().numpy()[0] for p in vm.density_planes]
    dl = [q.detach().double().numpy()[0, :, :, 0] for q in vm.density_lines]
    cp = [p.detach().double().numpy()[0] for p in vm.colour_planes]
    cl = [q.detach().double().numpy()[0, :, :, 0] for q in vm.colour_lines]
    basis = vm.basis.detach().double().numpy()
    out = []
    for pt in u:

        def comps(planes, lines, pt=pt):
            vals = []
            for m, ((a, b), c) in enumerate(zip(PLANE_AXES, LINE_AXES, strict=True)):
                for k in range(planes[m].shape[0] if planes else 0):
                    # bilinear: interpolate along a (width) in the rows around b, then along b
                    rows = np.array([_lerp(planes[m][k, j], pt[a]) for j in range(planes[m].shape[1])])
                    vals.append(_lerp(rows, pt[b]) * _lerp(lines[m][k], pt[c]))
            return np.array(vals)

        dens = comps(dp, dl).sum() if dp else 0.0
        out.append(np.concatenate([[dens], basis @ comps(cp, cl)]))
    return np.array(out)


def test_vm_query_matches_a_float64_reference_forward_and_backward():
    vm = _vm()
    rng = np.random.default_rng(1)
    u = rng.uniform(0, 1, size=(40, 3))
    u[0] = [0, 0, 0]
    u[1] = [1, 1, 1]  # the far corner (border)
    got = vm_query(vm, torch.from_numpy(u))
    np.testing.assert_allclose(got.detach().numpy(), _reference(vm, u), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(vm_query(vm, torch.from_numpy(u), density_only=True).detach().numpy()[:, 0],
                               _reference(vm, u)[:, 0], rtol=1e-10, atol=1e-12)  # fmt: skip
    # backward: the float32 factors' gradient against the float64 one (same values), rtol 1e-4
    probe = torch.from_numpy(rng.uniform(-1, 1, size=got.shape))
    (got * probe).sum().backward()
    vm32 = vm_from_leaves([t.detach().float().requires_grad_(True) for t in vm.leaves()], density=True)
    (vm_query(vm32, torch.from_numpy(u).float()).double() * probe).sum().backward()
    for a, b in zip(vm32.leaves(), vm.leaves(), strict=True):
        assert a.grad is not None and b.grad is not None
        torch.testing.assert_close(a.grad.double(), b.grad, rtol=1e-4, atol=1e-5)
    # colour factors only: density 0 from the factors
    only = _vm(density=0)
    assert torch.all(vm_query(only, torch.from_numpy(u), density_only=True) == 0)


def test_packed_rendering_of_a_grid_plus_vm_field_with_a_density_scale_matches_the_reference():
    g = torch.Generator().manual_seed(3)
    shape = (6, 7, 8)
    grid = (torch.randn((1, 4, *shape), generator=g) * 2.0).requires_grad_(True)
    occ = torch.rand(shape, generator=g) > 0.3
    vm = _vm(density=0, dtype=torch.float32)
    lo, hi = torch.tensor([-1.0, -1.0, -1.0]), torch.tensor([1.0, 1.0, 1.0])
    f = FieldTensors(grid, lo, hi, occ, -2.0, 48, 0.05, None, vm, density_scale=7.5)
    c2w = torch.eye(4)
    c2w[2, 3] = -3.0
    K = torch.tensor([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    px, py = torch.rand(25, generator=g) * 16, torch.rand(25, generator=g) * 12
    o, d = pixel_rays(c2w, K, px, py)
    bg = torch.tensor([0.2, 0.4, 0.6])
    rgb, acc = render_rays(f, o, d, bg)
    (rgb.sum() + acc.sum()).backward()
    # reference: every sample, float64 trilinear (grid_sample in float64) + the float64 VM reference formula
    tn, tf = ray_aabb(o, d, lo, hi, f.near)
    g64 = grid.detach().double()
    for i in range(o.shape[0]):
        s = f.n_samples
        t = tn[i].double() + (torch.arange(s, dtype=torch.float64) + 0.5) / s * (tf[i] - tn[i]).double()
        pts = o[i].double() + t[:, None] * d[i].double()
        u = ((pts - lo.double()) / (hi - lo).double()).clamp(0, 1)
        raw = torch.nn.functional.grid_sample(g64, (u * 2 - 1).reshape(1, 1, 1, -1, 3), align_corners=True,
                                              padding_mode="border").reshape(4, -1).T  # fmt: skip
        raw = raw + torch.from_numpy(_reference(vm, u.numpy()))
        dims = torch.tensor([shape[2], shape[1], shape[0]], dtype=torch.float64)
        idx = torch.round(u * (dims - 1)).long()
        keep = occ[idx[:, 2], idx[:, 1], idx[:, 0]] & (tf[i] > tn[i])
        sig = torch.where(keep, 7.5 * torch.nn.functional.softplus(raw[:, 0] - 2.0), 0.0)
        delta = ((tf[i] - tn[i]).double() / s).expand(s)
        ref_rgb, ref_acc = composite_ray(sig, torch.sigmoid(raw[:, 1:]), delta, bg.double())
        torch.testing.assert_close(rgb[i].double(), ref_rgb, rtol=1e-4, atol=1e-5)
        torch.testing.assert_close(acc[i].double(), ref_acc, rtol=1e-4, atol=1e-5)
    assert all(t.grad is not None and torch.isfinite(t.grad).all() for t in vm.leaves())
    assert float(vm.colour_planes[0].grad.abs().sum()) > 0


def test_model_file_round_trip_with_vm_factors_and_an_older_file(tmp_path):
    g = np.random.default_rng(0).normal(size=(4, 3, 4, 5)).astype(np.float32)
    vm = vm_arrays(_vm(density=0, dtype=torch.float32))
    f = FieldArrays(g, np.array([-1.0, -1, -1]), np.array([1.0, 1, 1]), np.ones((3, 4, 5), bool), -3.0, 64, 0.1,
                    vm=vm, density_scale=100.0)  # fmt: skip
    write_field(f, tmp_path / "m.npz")
    r = read_field(tmp_path / "m.npz")
    assert r.density_scale == 100.0 and r.vm is not None and not r.vm.density_planes
    for a, b in zip(r.vm.arrays().values(), vm.arrays().values(), strict=True):
        np.testing.assert_array_equal(a, b)
    t = FieldTensors.from_arrays(r, torch.device("cpu"))
    assert t.vm is not None and t.vm.dims == DIMS and t.density_scale == 100.0
    # a version-2 file (no density_scale, no factors) reads with scale 1
    with open(tmp_path / "v2.npz", "wb") as fh:
        np.savez(fh, format=np.array("eigs-field"), version=np.array(2), grid=g, lo=f.lo, hi=f.hi,
                 occupancy=f.occupancy, density_shift=np.array(-3.0), n_samples=np.array(64),
                 near=np.array(0.1))  # fmt: skip
    old = read_field(tmp_path / "v2.npz")
    assert old.density_scale == 1.0 and old.vm is None
    # a basis with the wrong channel count is refused
    bad = FieldArrays(g[:2], f.lo, f.hi, f.occupancy, -3.0, 64, 0.1, vm=vm)
    with pytest.raises(EigsError, match="basis"):
        write_field(bad, tmp_path / "bad.npz")


def test_growth_is_exact_on_factors_linear_along_each_axis():
    vm = _vm(density=1, colour=2)
    with torch.no_grad():  # planes and lines linear in their coordinates: bilinear × linear resampling is exact
        for ps, ls in ((vm.density_planes, vm.density_lines), (vm.colour_planes, vm.colour_lines)):
            for p in ps:
                h, w = p.shape[2:]
                yy, xx = torch.meshgrid(torch.linspace(0, 1, h, dtype=p.dtype), torch.linspace(0, 1, w, dtype=p.dtype),
                                        indexing="ij")  # fmt: skip
                p.copy_((0.3 + 0.5 * xx - 0.7 * yy + 0.2 * xx * yy).expand_as(p))
            for q in ls:
                q.copy_(torch.linspace(-1, 2, q.shape[2], dtype=q.dtype)[None, None, :, None].expand_as(q))
    u = torch.from_numpy(np.random.default_rng(2).uniform(0, 1, size=(30, 3)))
    before = vm_query(vm, u)
    big = grow_vm(vm, (13, 9, 6))
    assert big.dims == (13, 9, 6) and big.basis is vm.basis
    torch.testing.assert_close(vm_query(big, u), before, rtol=1e-10, atol=1e-10)


def test_vm_total_variation_gradient_matches_autograd():
    vm = _vm(density=1, colour=2)
    vm_tv_grad_(vm, 0.3, 0.05)  # grads created (zeros + the TV gradient)
    got = [t.grad.clone() for t in vm.leaves()[:-1]]
    ref = vm_from_leaves([t.detach().clone().requires_grad_(True) for t in vm.leaves()], density=True)

    def tv(ts):
        total = 0
        for x in ts:
            dims = [d for d in (2, 3) if x.shape[d] > 1]
            total = total + sum((x.diff(dim=d) ** 2).mean() for d in dims) / len(dims)
        return total

    loss = 0.3 * tv([*ref.density_planes, *ref.density_lines]) + 0.05 * tv([*ref.colour_planes, *ref.colour_lines])
    loss.backward()
    for a, b in zip(got, ref.leaves()[:-1], strict=True):
        torch.testing.assert_close(a, b.grad, rtol=1e-10, atol=1e-12)
