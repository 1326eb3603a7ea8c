"""Render paths for scenes without ground truth (eigs.util.cameras): orbit for all-around captures, ellipse for
forward-facing ones."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.util.cameras import ellipse_cameras, forward_facing, orbit_cameras, render_path


def look_at(c, target, up=(0.0, -1.0, 0.0)):
    z = np.asarray(target, float) - c
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, :3] = np.stack([x, np.cross(z, x), z], 1)
    m[:3, 3] = c
    return m


def ring(n=12, r=3.0):
    return np.stack([look_at(np.array([r * np.cos(a), 0.0, r * np.sin(a)]), [0, 0, 0])
                     for a in np.linspace(0, 2 * np.pi, n, endpoint=False)])  # fmt: skip


def slider(n=21):
    """Cameras on a line along x, all looking along +z (a linear slider)."""
    out = np.tile(np.eye(4), (n, 1, 1))
    out[:, 0, 3] = np.linspace(-1, 1, n)
    return out


def test_forward_facing_tells_a_slider_from_a_ring():
    assert forward_facing(slider())
    assert not forward_facing(ring())
    assert render_path(slider(), 5)[1] == "ellipse" and render_path(ring(), 5)[1] == "orbit"


def test_ellipse_of_a_slider_spans_its_track_and_looks_ahead():
    cams = ellipse_cameras(slider(), 8)
    centres = cams[:, :3, 3]
    # in the plane z = 0 through the mean centre; semi-axis along x = 90th percentile of |x| = 0.9; none across
    np.testing.assert_allclose(centres[:, 2], 0.0, atol=1e-12)
    np.testing.assert_allclose(centres[:, 1], 0.0, atol=1e-12)
    assert np.abs(centres[:, 0]).max() == pytest.approx(0.9, abs=1e-12)
    # every camera looks forward (+z) and is a rotation
    for m in cams:
        assert m[2, 2] > 0.5
        np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)


def test_orbit_cameras_circle_the_ring_and_look_at_its_centre():
    cams = orbit_cameras(ring(), 10)
    c = cams[:, :3, 3]
    np.testing.assert_allclose(np.linalg.norm(c, axis=1), 3.0, atol=1e-6)
    # the optical axis of every camera passes through the origin
    z = cams[:, :3, 2]
    np.testing.assert_allclose(np.cross(z, -c), 0.0, atol=1e-6)
