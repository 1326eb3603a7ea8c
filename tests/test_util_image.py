"""util.image and util.cache: the sRGB pair, the one float → uint8 rule, the PNG writers, the cache directory."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from eigs.util.image import to_uint8, write_png


def test_rounding_rule_is_exact_on_uint8_values_and_rounds_half_up():
    k = np.arange(256)
    np.testing.assert_array_equal(to_uint8(k / 255.0), k.astype(np.uint8))
    np.testing.assert_array_equal(to_uint8(np.array([(0.5) / 255, 1.5 / 255, -1.0, 2.0, np.nan])), [1, 2, 0, 255, 0])


def test_png_round_trip_rgb_and_grey(tmp_path):
    rng = np.random.default_rng(0)
    rgb = rng.integers(0, 256, (5, 7, 3)).astype(np.uint8)
    write_png(tmp_path / "a.png", rgb.astype(np.float64) / 255.0)
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "a.png"))[..., ::-1], rgb)
    write_png(tmp_path / "g.png", rgb[..., :1])
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "g.png"), cv2.IMREAD_UNCHANGED), rgb[..., 0])


def test_srgb_pair_matches_the_standard_and_inverts():
    """IEC 61966-2-1 closed form at known points, both branches, clipping, and the round trip."""
    from eigs.util.image import linear_to_srgb, srgb_to_linear

    assert srgb_to_linear(np.array([0.5]))[0] == pytest.approx(((0.5 + 0.055) / 1.055) ** 2.4, abs=1e-15)
    assert srgb_to_linear(np.array([0.04]))[0] == pytest.approx(0.04 / 12.92, abs=1e-15)
    np.testing.assert_allclose(srgb_to_linear(np.array([-0.5, 1.5])), [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(linear_to_srgb(np.array([-0.5, 1.5])), [0.0, 1.0], atol=1e-15)
    x = np.linspace(0.0, 1.0, 1001)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-12)
    assert srgb_to_linear(np.float32(0.5)).dtype == np.float64


def test_rgba_png_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    rgba = rng.integers(0, 256, (4, 6, 4)).astype(np.uint8)
    write_png(tmp_path / "a.png", rgba)
    np.testing.assert_array_equal(cv2.imread(str(tmp_path / "a.png"), cv2.IMREAD_UNCHANGED)[..., [2, 1, 0, 3]], rgba)


def test_one_cache_directory_and_one_variable(tmp_path, monkeypatch):
    """The rasterizer build cache and the resource download cache are the same directory, from EIGS_CACHE_DIR,
    else XDG_CACHE_HOME/eigs, else ~/.cache/eigs."""
    from pathlib import Path

    from eigs.metrics import resources
    from eigs.render import _backend
    from eigs.util.cache import cache_dir

    monkeypatch.setenv("EIGS_CACHE_DIR", str(tmp_path / "a"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert cache_dir() == resources.cache_dir() == _backend.cache_dir() == tmp_path / "a"
    monkeypatch.delenv("EIGS_CACHE_DIR")
    assert cache_dir() == resources.cache_dir() == tmp_path / "x" / "eigs"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert cache_dir() == Path.home() / ".cache" / "eigs"


def test_latent_png_writer_uses_the_one_rule(tmp_path):
    """The EDI stage and the SfM fallback write latent PNGs with one writer: ⌊255 v + 0.5⌋ (half up, so
    0.5/255 → 1 where round-half-even would give 0)."""
    from eigs.artifacts.edi import latent_png_name, write_latent_pngs

    lat = np.zeros((2, 3, 2, 2, 3), np.float32)
    lat[1, 2, 0, 0] = [0.5 / 255, 2.5 / 255, 1.0]
    assert write_latent_pngs(lat, tmp_path / "all") == 6
    assert write_latent_pngs(lat, tmp_path / "some", [(1, 2)]) == 1
    assert sorted(p.name for p in (tmp_path / "some").iterdir()) == [latent_png_name(1, 2)]
    img = cv2.imread(str(tmp_path / "all" / latent_png_name(1, 2)))[..., ::-1]
    np.testing.assert_array_equal(img[0, 0], to_uint8(lat[1, 2, 0, 0]))
    np.testing.assert_array_equal(img[0, 0], [1, 3, 255])
