"""Forward: the tile kernels equal the dense reference (docs/rasterizer.md, "Semantics")."""

from __future__ import annotations

import pytest
import torch
from render_scenes import random_scene, reference

from eigs.render import _backend, rasterize
from eigs.render._wrapper import rasterize_cpu

ISAS = _backend.available_isas()


@pytest.mark.parametrize(
    ("n", "width", "height", "d", "seed"),
    [(400, 45, 38, 3, 0), (300, 64, 48, 1, 1), (250, 33, 50, 5, 2), (600, 40, 40, 3, 3)],
)
def test_forward_matches_dense_reference(n: int, width: int, height: int, d: int, seed: int) -> None:
    scene = random_scene(n, width, height, d=d, seed=seed)
    image, alpha, info = rasterize(*scene.args())
    ref_image, ref_alpha, ref_info = reference(scene)
    near = ref_info["near_threshold"]
    ok = ~near
    # pixels where some Gaussian sits within 1e-6 of the 1/255 or 1e-4 thresholds are excluded and counted
    assert int(near.sum()) <= 0.01 * width * height, f"{int(near.sum())} pixels excluded"
    assert (image.double() - ref_image)[ok].abs().max() <= 1e-5
    assert (alpha.double() - ref_alpha)[ok].abs().max() <= 1e-5
    # projection agrees with the reference for kept Gaussians; culled ones have radii 0
    kept = info["radii"][:, 0] > 0
    assert bool((kept <= ref_info["kept"]).all())
    torch.testing.assert_close(info["means2d"][kept].double(), ref_info["means2d"][kept], atol=1e-3, rtol=1e-5)
    torch.testing.assert_close(info["conics"][kept].double(), ref_info["conics"][kept], atol=1e-6, rtol=1e-4)
    assert info["n_isects"] > n // 2


@pytest.mark.parametrize("isa", ISAS)
def test_every_isa_gives_identical_images(isa: str) -> None:
    scene = random_scene(500, 50, 41, seed=7)
    base = rasterize_cpu(*scene.args(), isa=_backend.isa_code("baseline"))
    out = rasterize_cpu(*scene.args(), isa=_backend.isa_code(isa))
    # -ffp-contract=off and the shared per-pair header make the variants bit-identical
    assert torch.equal(base[0], out[0])
    assert torch.equal(base[1], out[1])


def test_float64_forward_matches_reference() -> None:
    scene = random_scene(200, 36, 30, seed=4, dtype=torch.float64)
    image, alpha, _ = rasterize(*scene.args())
    ref_image, ref_alpha, ref_info = reference(scene)
    ok = ~ref_info["near_threshold"]
    assert (image - ref_image)[ok].abs().max() <= 1e-10
    assert (alpha - ref_alpha)[ok].abs().max() <= 1e-10


def test_saturated_stack_terminates_like_reference() -> None:
    # alpha -> 1 stacks: many nearly opaque, large Gaussians on top of each other (early stop everywhere)
    scene = random_scene(300, 40, 34, seed=5, opacity=(0.9, 1.0), log_scale=(-1.0, -0.3), margin=0.0)
    image, alpha, _ = rasterize(*scene.args())
    ref_image, ref_alpha, ref_info = reference(scene)
    ok = ~ref_info["near_threshold"]
    assert (image.double() - ref_image)[ok].abs().max() <= 1e-5
    assert float((ref_alpha > 0.999).double().mean()) > 0.5  # the stack really saturates
    assert (alpha.double() - ref_alpha)[ok].abs().max() <= 1e-5


def test_background_and_empty_pixels() -> None:
    scene = random_scene(5, 48, 40, seed=6, margin=0.0, log_scale=(-5.0, -4.5))
    image, alpha, _ = rasterize(*scene.args())
    far = alpha == 0
    assert bool(far.any())
    assert torch.equal(image[far], scene.background.expand(int(far.sum()), -1))


def test_large_gaussian_box_is_conservative() -> None:
    # One big, elongated Gaussian over many tiles, with opacities just above the cull threshold: every pixel
    # with alpha >= 1/255 in the dense definition must be drawn by the tile kernel.
    for seed, o in enumerate([1.0 / 255 * 1.05, 0.05, 0.5, 0.99]):
        scene = random_scene(1, 80, 64, seed=10 + seed, margin=-20.0, log_scale=(-1.6, -0.8))
        scene.opacities.fill_(o)
        image, alpha, _ = rasterize(*scene.args())
        _, ref_alpha, ref_info = reference(scene)
        ok = ~ref_info["near_threshold"]
        assert ((ref_alpha > 0) & ok).any()
        assert torch.equal((alpha > 0)[ok], (ref_alpha > 0)[ok])
        assert (alpha.double() - ref_alpha)[ok].abs().max() <= 1e-6
