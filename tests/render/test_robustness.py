"""Robustness: degenerate inputs never crash or emit NaN, and culled Gaussians get zero gradients."""

from __future__ import annotations

import math

import pytest
import torch
from render_scenes import random_scene, reference

from eigs.render import rasterize


def _render_and_backward(scene, seed: int = 0):
    image, alpha, info = rasterize(*scene.args())
    g = torch.Generator().manual_seed(seed)
    v_image = torch.randn(image.shape, generator=g, dtype=image.dtype)
    v_alpha = torch.randn(alpha.shape, generator=g, dtype=alpha.dtype)
    ((image * v_image).sum() + (alpha * v_alpha).sum()).backward()
    return image, alpha, info


def _all_finite(*tensors) -> bool:
    return all(bool(torch.isfinite(t).all()) for t in tensors)


def test_zero_gaussians() -> None:
    scene = random_scene(0, 40, 30).to(torch.float32, grad=True)
    image, alpha, info = _render_and_backward(scene)
    assert image.shape == (30, 40, 3) and alpha.shape == (30, 40)
    assert torch.equal(image, scene.background.detach().expand(30, 40, 3))
    assert float(alpha.detach().abs().max()) == 0.0
    assert info["n_isects"] == 0 and info["radii"].shape == (0, 2)
    assert scene.means.grad.shape == (0, 3) and scene.quats.grad.shape == (0, 4)
    # T = 1 everywhere: the background gradient is the sum of the image cotangent
    s2 = random_scene(0, 40, 30).to(torch.float32, grad=True)
    image, alpha, _ = rasterize(*s2.args())
    (image.sum() + alpha.sum()).backward()
    assert torch.equal(s2.background.grad, torch.full((3,), 1200.0))


def _degenerate(kind: str, scene) -> torch.Tensor:
    """Make the first half of the Gaussians degenerate in one way; returns the degenerate mask."""
    n = scene.means.shape[0]
    bad = torch.zeros(n, dtype=torch.bool)
    bad[: n // 2] = True
    with torch.no_grad():
        if kind == "nan_means":
            scene.means[bad, 1] = math.nan
        elif kind == "inf_means":
            scene.means[bad, 0] = math.inf
        elif kind == "nan_quats":
            scene.quats[bad, 2] = math.nan
        elif kind == "inf_scales":
            scene.scales[bad, 0] = math.inf
        elif kind == "nan_opacity":
            scene.opacities[bad] = math.nan
        elif kind == "nan_colors":
            scene.colors[bad, 0] = math.nan
        elif kind == "zero_scales":
            scene.scales[bad, 1] = 0.0
        elif kind == "tiny_scales":
            scene.scales[bad] = 1e-9
        elif kind == "negative_scales":
            scene.scales[bad, 2] = -0.1
        elif kind == "zero_quats":
            scene.quats[bad] = 0.0
        elif kind == "low_opacity":
            scene.opacities[bad] = 1.0 / 255.0 * 0.999
        elif kind == "behind_camera":
            scene.means[bad] = scene.means[bad] - 10.0 * scene.viewmat[2, :3]
        else:
            raise AssertionError(kind)
    return bad


KINDS = ["nan_means", "inf_means", "nan_quats", "inf_scales", "nan_opacity", "nan_colors", "zero_scales",
         "tiny_scales", "negative_scales", "zero_quats", "low_opacity", "behind_camera"]  # fmt: skip


@pytest.mark.parametrize("kind", KINDS)
def test_degenerate_gaussians_are_culled(kind: str) -> None:
    scene = random_scene(60, 40, 32, seed=1).to(torch.float32, grad=True)
    bad = _degenerate(kind, scene)
    image, alpha, info = _render_and_backward(scene)
    assert _all_finite(image, alpha, info["means2d"], info["conics"])
    assert bool((info["radii"][bad] == 0).all())
    for t in scene.leaves():
        assert _all_finite(t.grad), kind
    for t in (scene.means, scene.quats, scene.scales, scene.opacities, scene.colors):
        assert float(t.grad[bad].abs().max()) == 0.0, kind
    # the healthy half renders exactly as if the degenerate half did not exist
    ok = ~bad
    clean = random_scene(60, 40, 32, seed=1)
    sub = type(clean)(clean.means[ok], clean.quats[ok], clean.scales[ok], clean.opacities[ok], clean.colors[ok],
                      clean.viewmat, clean.K, 40, 32, clean.background)  # fmt: skip
    image2, alpha2, _ = rasterize(*sub.args())
    assert torch.equal(image.detach(), image2) and torch.equal(alpha.detach(), alpha2)
    # and the dense reference agrees
    _, ref_alpha, ref_info = reference(scene)
    assert bool((ref_info["kept"][bad] == 0).all())
    okpx = ~ref_info["near_threshold"]
    assert (alpha.detach().double() - ref_alpha)[okpx].abs().max() <= 1e-5


def test_far_away_and_huge_coordinates_stay_finite() -> None:
    # means scaled by 1e30 (valid, far away: sub-pixel splats) and by 1e38 (camera-space z overflows to inf)
    for factor in (1e30, 1e38):
        scene = random_scene(40, 40, 32, seed=6).to(torch.float32, grad=True)
        with torch.no_grad():
            scene.means[:20] *= factor
        image, alpha, _ = _render_and_backward(scene)
        assert _all_finite(image, alpha, *[t.grad for t in scene.leaves()])
        _, ref_alpha, ref_info = reference(scene)
        ok = ~ref_info["near_threshold"]
        assert (alpha.detach().double() - ref_alpha)[ok].abs().max() <= 1e-5


def test_all_culled() -> None:
    scene = random_scene(30, 32, 32, seed=2).to(torch.float32, grad=True)
    with torch.no_grad():
        scene.opacities.fill_(0.001)
    image, alpha, info = _render_and_backward(scene)
    assert info["n_isects"] == 0
    assert torch.equal(image.detach(), scene.background.detach().expand(32, 32, 3))
    assert all(float(t.grad.abs().max()) == 0.0 for t in scene.leaves()[:5])


def test_alpha_one_stack_no_nan() -> None:
    # 50 opaque Gaussians at the same place: alpha hits the 0.99 cap, T would underflow without the early stop
    scene = random_scene(50, 32, 32, seed=3, opacity=(1.0, 1.0), log_scale=(-1.0, -1.0), margin=-14.0)
    with torch.no_grad():
        scene.means[:] = scene.means[0]
    s = scene.to(torch.float32, grad=True)
    image, alpha, _ = _render_and_backward(s)
    assert _all_finite(image, alpha, *[t.grad for t in s.leaves()])
    assert float(alpha.detach().max()) <= 1 - 1e-4 + 1e-7
    # only the first two Gaussians (ties by index) reach the centre pixels: 0.99 then stop (T = 0.01 * 0.01)
    assert float(s.colors.grad[2:].abs().max()) < float(s.colors.grad[:2].abs().max())


def test_4k_image_with_huge_gaussians_no_overflow() -> None:
    # A 4K frame, Gaussians close to the near plane with boxes of ~1e7 px and one at 1e9 px off-screen:
    # tile bounds must clamp in 64-bit (no int overflow), and the image stays finite.
    W, H = 3840, 2160
    scene = random_scene(8, W, H, seed=4, log_scale=(-3.0, -2.0)).to(torch.float32, grad=True)
    with torch.no_grad():
        scene.scales[:3] = 50.0
        cam = torch.tensor([[0.0, 0.0, 0.011], [0.5, -0.4, 0.02], [1e7, 0.0, 1.0]], dtype=torch.float64)
        R, t = scene.viewmat[:3, :3].double(), scene.viewmat[:3, 3].double()
        scene.means[:3] = ((cam - t) @ R).float()
    image, alpha, info = _render_and_backward(scene)
    assert image.shape == (H, W, 3)
    assert _all_finite(image, alpha, *[t.grad for t in scene.leaves()])
    assert int(info["radii"][0].max()) > 10_000
    assert 0 < info["n_isects"] <= 8 * (W // 16) * (H // 16 + 1)  # at most every tile per Gaussian


def test_principal_point_far_off_centre() -> None:
    scene = random_scene(200, 40, 36, seed=5)
    scene.K[0, 2], scene.K[1, 2] = -15.0, 60.0  # principal point outside the image
    image, alpha, _ = rasterize(*scene.args())
    ref_image, ref_alpha, ref_info = reference(scene)
    ok = ~ref_info["near_threshold"]
    assert _all_finite(image, alpha)
    assert (image.double() - ref_image)[ok].abs().max() <= 1e-5


def test_bad_arguments_raise() -> None:
    scene = random_scene(4, 16, 16)
    args = list(scene.args())
    with pytest.raises(ValueError, match="quats"):
        rasterize(args[0], args[1][:, :3], *args[2:])
    with pytest.raises(ValueError, match="backend"):
        rasterize(*args, backend="opengl")
    with pytest.raises(ValueError, match="CUDA"):
        rasterize(*args, backend="gsplat")
    with pytest.raises(TypeError, match="float32 or float64"):
        rasterize(args[0].half(), *args[1:])
    bad_k = args[6].clone()
    bad_k[0, 0] = math.nan
    with pytest.raises(ValueError, match="finite"):
        rasterize(*args[:6], bad_k, *args[7:])


def test_double_backward_raises() -> None:
    # The C++ Functions are once-differentiable: differentiating a gradient must raise, not act as a constant.
    scene = random_scene(30, 24, 20, seed=2).to(torch.float64, grad=True)
    image, alpha, _ = rasterize(*scene.args())
    (g_means,) = torch.autograd.grad((image.sum() + alpha.sum(),), (scene.means,), create_graph=True)
    assert g_means.requires_grad  # under create_graph the gradient carries the error node
    with pytest.raises(RuntimeError, match="not differentiable"):
        g_means.sum().backward()


def test_backward_rejects_a_binning_that_names_no_gaussian() -> None:
    # The backward groups the pair slots by the Gaussian ids of the binning it is given; an id outside 0..N-1
    # must be refused with a clear error instead of writing out of bounds.
    from eigs.render import _backend
    from eigs.render._wrapper import camera_list

    C = _backend.load()
    scene = random_scene(50, 40, 30, seed=3)
    means, quats, scales, opac, colors, viewmat, K, W, H, bg = scene.args()
    cam = camera_list(viewmat, K, means.dtype)
    m2, con, dep, ext, radii = C.project_fwd(means, quats, scales, opac, colors, cam, W, H)
    offs, ids = C.isect_tiles(m2, ext, dep, radii, W, H, con, opac)
    image, alpha, trans, last, work = C.rasterize_fwd(m2, con, colors, opac, ext, bg, offs, ids, W, H, 0)
    v_image, v_alpha = torch.ones_like(image), torch.ones_like(alpha)
    for bad in (50, -1):
        wrong = ids.clone()
        wrong[len(wrong) // 2] = bad
        with pytest.raises(RuntimeError, match="not a Gaussian of 50"):
            C.rasterize_bwd(m2, con, colors, opac, ext, bg, offs, wrong, W, H, trans, last, work, v_image, v_alpha, 0)
