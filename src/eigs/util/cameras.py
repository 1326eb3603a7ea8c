"""Camera paths shared by rendering and evaluation (NumPy only)."""

from __future__ import annotations

import numpy as np


def orbit_cameras(c2w: np.ndarray, n: int) -> np.ndarray:
    """(n, 4, 4) cameras on a circle through the training cameras' mean radius and height, looking at the point
    closest to every training camera's optical axis; ``c2w`` (M, 4, 4) valid training cameras, OpenCV axes."""
    centres, fwd = c2w[:, :3, 3], c2w[:, :3, 2]
    # the point closest (least squares) to every optical axis
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for c, d in zip(centres, fwd, strict=True):
        proj = np.eye(3) - np.outer(d, d)
        a += proj
        b += proj @ c
    target = np.linalg.lstsq(a + 1e-9 * np.eye(3), b, rcond=None)[0]
    up = -c2w[:, :3, 1].mean(axis=0)  # OpenCV y points down
    up /= max(np.linalg.norm(up), 1e-12)
    rel = centres - target
    height = float((rel @ up).mean())
    radial = rel - np.outer(rel @ up, up)
    radius = float(np.linalg.norm(radial, axis=1).mean())
    e1 = radial[0] / max(np.linalg.norm(radial[0]), 1e-12)
    e2 = np.cross(up, e1)
    out = np.zeros((n, 4, 4))
    for i, phi in enumerate(np.linspace(0.0, 2 * np.pi, n, endpoint=False)):
        c = target + height * up + radius * (np.cos(phi) * e1 + np.sin(phi) * e2)
        z = target - c
        z /= max(np.linalg.norm(z), 1e-12)
        x = np.cross(z, up)
        x /= max(np.linalg.norm(x), 1e-12)
        y = np.cross(z, x)
        out[i, :3, :3] = np.stack([x, y, z], axis=1)
        out[i, :3, 3] = c
        out[i, 3, 3] = 1.0
    return out
