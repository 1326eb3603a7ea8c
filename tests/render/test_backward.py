"""Backward: gradients equal the reference's autograd (float32) and pass gradcheck (float64)."""

from __future__ import annotations

import pytest
import torch
from render_scenes import LEAF_NAMES, random_scene, reference, rel_l2

from eigs.render import _backend, means2d_grad, rasterize
from eigs.render._wrapper import rasterize_cpu
from eigs.render.reference import render_reference

ISAS = _backend.available_isas()


def _grads(fn, scene, v_image, v_alpha, retain_means2d: bool = False):
    image, alpha, info = fn(*scene.args())
    if retain_means2d:
        info["means2d"].retain_grad()
    loss = (image * v_image.to(image.dtype)).sum() + (alpha * v_alpha.to(alpha.dtype)).sum()
    loss.backward()
    return [t.grad for t in scene.leaves()], info


@pytest.mark.parametrize(
    ("n", "width", "height", "d", "seed", "isa"),
    [(300, 45, 38, 3, 0, i) for i in ISAS]
    + [(250, 40, 33, 1, 1, ISAS[-1]), (200, 36, 40, 4, 2, ISAS[-1]), (400, 48, 48, 3, 3, ISAS[-1])],
)
def test_gradients_match_reference(n: int, width: int, height: int, d: int, seed: int, isa: str) -> None:
    base = random_scene(n, width, height, d=d, seed=seed, opacity=(0.02, 1.0))
    g = torch.Generator().manual_seed(100 + seed)
    _, _, ref_info0 = reference(base)
    keep = (~ref_info0["near_threshold"]).double()
    # random cotangents, zero on the excluded near-threshold pixels
    v_image = torch.randn(height, width, d, generator=g, dtype=torch.float64) * keep[..., None]
    v_alpha = torch.randn(height, width, generator=g, dtype=torch.float64) * keep

    ours = base.to(torch.float32, grad=True)
    code = _backend.isa_code(isa)
    got, info = _grads(lambda *a: rasterize_cpu(*a, isa=code), ours, v_image, v_alpha, retain_means2d=True)
    ref = base.to(torch.float64, grad=True)
    want, ref_info = _grads(render_reference, ref, v_image, v_alpha, retain_means2d=True)
    for name, x, y in zip(LEAF_NAMES, got, want, strict=True):
        assert torch.isfinite(x).all(), name
        assert rel_l2(x, y) <= 1e-3, f"{name}: rel L2 {rel_l2(x, y):.2e}"
    # 2-D mean gradients are in pixel units, like the reference's d loss / d means2d
    kept = info["radii"][:, 0] > 0
    assert rel_l2(means2d_grad(info)[kept], ref_info["means2d"].grad[kept]) <= 1e-3


@pytest.mark.parametrize("d", [3, 1, 2])
def test_every_isa_gives_identical_gradients(d: int) -> None:
    # the backward sums each Gaussian's lanes in one fixed order over the 16 lanes of a tile row whatever the
    # ISA's vector width (4, 8 or 16 floats), so every variant gives the same gradients bit for bit (d = 2: the
    # kernel without a compile-time channel count)
    scene = random_scene(400, 50, 41, d=d, seed=13)
    g = torch.Generator().manual_seed(13)
    v_image = torch.randn(41, 50, d, generator=g, dtype=torch.float64)
    v_alpha = torch.randn(41, 50, generator=g, dtype=torch.float64)
    results = []
    for isa in ISAS:
        code = _backend.isa_code(isa)
        grads, _ = _grads(lambda *a, c=code: rasterize_cpu(*a, isa=c), scene.to(torch.float32, grad=True), v_image,
                          v_alpha)  # fmt: skip
        results.append(grads)
    assert float(results[0][0].abs().max()) > 0
    for other in results[1:]:
        for name, x, y in zip(LEAF_NAMES, results[0], other, strict=True):
            assert torch.equal(x, y), name


def test_non_finite_cotangent_reaches_only_the_gaussians_at_its_pixel() -> None:
    # a NaN in v_image at one pixel may spoil the gradients of the Gaussians composited there, never those of
    # Gaussians that merely share its tile row (the kernel evaluates whole lane groups and masks the rest)
    scene = random_scene(300, 40, 34, seed=14)
    p = (17, 21)

    def per_gaussian_grads(v_image: torch.Tensor) -> torch.Tensor:
        s = scene.to(torch.float32, grad=True)
        image, _, _ = rasterize(*s.args())
        image.backward(v_image)
        return torch.cat([t.grad.reshape(t.shape[0], -1) for t in s.leaves()[:5]], dim=1)

    one_hot = torch.zeros(34, 40, 3)
    one_hot[p] = 1.0
    touched = (per_gaussian_grads(one_hot) != 0).any(dim=1)
    v = torch.randn(34, 40, 3, generator=torch.Generator().manual_seed(14))
    v[p] = float("nan")
    bad = ~torch.isfinite(per_gaussian_grads(v)).all(dim=1)
    assert touched.any() and bad.any()
    assert not (bad & ~touched).any(), f"{int((bad & ~touched).sum())} Gaussians not at the pixel got non-finite grads"


def test_gradients_through_clamped_alpha_and_saturation() -> None:
    # opacities at 1 make o*G cross the 0.99 cap (no gradient flows there) and stacks terminate early
    base = random_scene(200, 40, 34, seed=8, opacity=(0.9, 1.0), log_scale=(-2.0, -1.0), margin=0.0)
    g = torch.Generator().manual_seed(8)
    _, _, ref_info0 = reference(base)
    keep = (~ref_info0["near_threshold"]).double()
    v_image = torch.randn(34, 40, 3, generator=g, dtype=torch.float64) * keep[..., None]
    v_alpha = torch.randn(34, 40, generator=g, dtype=torch.float64) * keep
    got, _ = _grads(rasterize, base.to(torch.float32, grad=True), v_image, v_alpha)
    want, _ = _grads(render_reference, base.to(torch.float64, grad=True), v_image, v_alpha)
    for name, x, y in zip(LEAF_NAMES, got, want, strict=True):
        assert rel_l2(x, y) <= 1e-3, f"{name}: rel L2 {rel_l2(x, y):.2e}"


@pytest.mark.parametrize(("seed", "width", "height", "fast"), [(0, 12, 10, False), (1, 20, 18, True)])
def test_gradcheck_float64(seed: int, width: int, height: int, fast: bool) -> None:
    base = random_scene(6, width, height, d=2, seed=20 + seed, opacity=(0.2, 0.9), log_scale=(-2.4, -1.8),
                        margin=0.0)  # fmt: skip
    s = base.to(torch.float64, grad=True)

    def f(means, quats, scales, opacities, colors, background):
        image, alpha, _ = rasterize(means, quats, scales, opacities, colors, s.viewmat, s.K, s.width, s.height,
                                    background)  # fmt: skip
        return image, alpha

    assert torch.autograd.gradcheck(f, tuple(s.leaves()), eps=1e-6, atol=1e-6, rtol=1e-4, fast_mode=fast)


def test_backward_is_deterministic_across_threads() -> None:
    base = random_scene(500, 64, 48, seed=9)
    g = torch.Generator().manual_seed(9)
    v_image = torch.randn(48, 64, 3, generator=g, dtype=torch.float64)
    v_alpha = torch.randn(48, 64, generator=g, dtype=torch.float64)
    before = torch.get_num_threads()
    try:
        results = []
        for threads in (1, 2, 2):
            torch.set_num_threads(threads)
            grads, _ = _grads(rasterize, base.to(torch.float32, grad=True), v_image, v_alpha)
            results.append(grads)
    finally:
        torch.set_num_threads(before)
    for other in results[1:]:
        for x, y in zip(results[0], other, strict=True):
            assert torch.equal(x, y)



def test_small_image_pipeline_is_bit_identical_across_threads() -> None:
    # 64 x 64 (16 tiles) with 1,200 Gaussians: projection and its backward run on several threads (grain of 256
    # Gaussians), the kernels on 2 or 3 (binning stays on one below 2,048 Gaussians; test_binning covers its
    # threads); image, alpha and every gradient (background included) must not depend on the thread count.
    base = random_scene(1200, 64, 64, seed=12)
    g = torch.Generator().manual_seed(12)
    v_image = torch.randn(64, 64, 3, generator=g, dtype=torch.float64)
    v_alpha = torch.randn(64, 64, generator=g, dtype=torch.float64)
    before = torch.get_num_threads()
    try:
        results = []
        for threads in (1, 2, 3, 2):
            torch.set_num_threads(threads)
            s = base.to(torch.float32, grad=True)
            image, alpha, info = rasterize(*s.args())
            loss = (image * v_image.float()).sum() + (alpha * v_alpha.float()).sum()
            loss.backward()
            results.append([image, alpha, info["flatten_ids"], info["tile_offsets"]] + [t.grad for t in s.leaves()])
    finally:
        torch.set_num_threads(before)
    assert float(results[0][-1].abs().max()) > 0  # the background gradient is exercised
    for other in results[1:]:
        for x, y in zip(results[0], other, strict=True):
            assert torch.equal(x, y)


def test_only_some_outputs_used() -> None:
    # backward with a cotangent for the image only, or the alpha only
    base = random_scene(100, 32, 32, seed=11)
    s = base.to(torch.float32, grad=True)
    image, alpha, _ = rasterize(*s.args())
    image.sum().backward()
    assert all(torch.isfinite(t.grad).all() for t in s.leaves())
    s2 = base.to(torch.float32, grad=True)
    _, alpha, _ = rasterize(*s2.args())
    alpha.sum().backward()
    assert float(s2.background.grad.abs().max()) == 0.0
    assert float(s2.opacities.grad.abs().max()) > 0.0
