"""util.image: the one float → uint8 rule and the PNG writer."""

from __future__ import annotations

import cv2
import numpy as np

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
