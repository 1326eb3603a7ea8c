"""Shared conversions: time units, polarity, pixels, view specs, exposure windows, intrinsics."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.ingest.options import parse_intrinsics, parse_views
from eigs.ingest.raw import in_windows, merge_windows
from eigs.ingest.timeconv import PolarityMapper, to_pixel, to_us


def test_integer_units():
    t = np.array([0, 1, 499, 500, 1499, 1500, 2500], np.int64)
    np.testing.assert_array_equal(to_us(t, "ns", "f"), [0, 0, 0, 1, 1, 2, 3])  # half up
    np.testing.assert_array_equal(to_us(t.astype(np.uint32), "us", "f"), t)
    np.testing.assert_array_equal(to_us(np.array([3], np.uint16), "ms", "f"), [3000])
    np.testing.assert_array_equal(to_us(np.array([2], np.int32), "s", "f"), [2_000_000])
    with pytest.raises(EigsError, match="overflow int64 µs"):
        to_us(np.array([2**62], np.int64), "s", "f")


def test_float_units():
    np.testing.assert_array_equal(to_us(np.array([1.0000005, 2.5e-6]), "s", "f"), [1_000_001, 3])
    # via integer ns (deterministic for ns-resolution decimal text): 2.4994 µs → 2499 ns → 2 µs, 2.4996 → 2500 → 3
    np.testing.assert_array_equal(to_us(np.array([1.5, 2.4994, 2.4996]), "us", "f"), [2, 2, 3])
    # beyond float64's ns range: exact only when within 0.25 µs of an integer µs
    np.testing.assert_array_equal(to_us(np.array([1_633_953_690.975950]), "s", "f"), [1_633_953_690_975_950])
    with pytest.raises(EigsError, match="too large to convert to µs exactly"):
        to_us(np.array([1.6339536909755e15 + 0.5]), "us", "f")
    with pytest.raises(EigsError, match="timestamp of event 11 is inf"):
        to_us(np.array([1.0, np.inf]), "s", "f", offset=10)


def test_polarity_encodings():
    np.testing.assert_array_equal(PolarityMapper("f")(np.array([0, 1, 1], np.uint8)), [-1, 1, 1])
    np.testing.assert_array_equal(PolarityMapper("f")(np.array([-1, 1], np.int8)), [-1, 1])
    np.testing.assert_array_equal(PolarityMapper("f")(np.array([True, False])), [1, -1])
    np.testing.assert_array_equal(PolarityMapper("f")(np.array([0.0, 1.0])), [-1, 1])
    m = PolarityMapper("f")
    m(np.array([0, 1]))
    with pytest.raises(EigsError, match="mixes 0 and −1"):
        m(np.array([-1, 1]))  # a later chunk with the other encoding
    with pytest.raises(EigsError, match="polarity of event 1 is 2"):
        PolarityMapper("f")(np.array([1, 2]))


def test_pixels():
    np.testing.assert_array_equal(to_pixel(np.array([0.0, 5.0]), 6, "x", "f"), [0, 5])
    with pytest.raises(EigsError, match="x of event 1 is 5.5, not an integer pixel"):
        to_pixel(np.array([0.0, 5.5]), 6, "x", "f")
    with pytest.raises(EigsError, match="y of event 0 is -1, outside the sensor"):
        to_pixel(np.array([-1, 2]), 6, "y", "f")


def test_views_spec():
    np.testing.assert_array_equal(parse_views("::10", 30), [0, 10, 20])
    np.testing.assert_array_equal(parse_views("0:3,7", 30), [0, 1, 2, 7])
    with pytest.raises(EigsError, match="view 30 does not exist"):
        parse_views("30", 30)
    with pytest.raises(EigsError, match="increasing order without repeats"):
        parse_views("3,1", 30)
    with pytest.raises(EigsError, match="selects no view"):
        parse_views("5:5", 30)


def test_windows():
    ex = np.array([[10, 20], [15, 30], [40, 50], [60, 60]], np.int64)
    s, e = merge_windows(ex)
    np.testing.assert_array_equal(s, [10, 40])
    np.testing.assert_array_equal(e, [30, 50])
    t = np.arange(0, 70, dtype=np.int64)
    brute = np.zeros(t.shape, bool)
    for a, b in ex:
        brute |= (t >= a) & (t < b)
    np.testing.assert_array_equal(in_windows(t, s, e), brute)


def test_intrinsics_file(tmp_path):
    f = tmp_path / "calib.txt"
    f.write_text("# fx fy cx cy k1 k2 p1 p2 k3\n199.1 198.8 132.2 110.7 -0.37 0.15 -0.0003 -0.0008 0.0\n")
    K, d = parse_intrinsics(str(f))
    np.testing.assert_allclose(K, [[199.1, 0, 132.7], [0, 198.8, 111.2], [0, 0, 1]])
    np.testing.assert_allclose(d, [-0.37, 0.15, -0.0003, -0.0008, 0.0])
    K, d = parse_intrinsics("10,11,4,3,0.1,0.01,0,0")
    np.testing.assert_allclose(d, [0.1, 0.01, 0, 0, 0])
    with pytest.raises(EigsError, match="focal lengths must be positive"):
        parse_intrinsics("0,11,4,3")
