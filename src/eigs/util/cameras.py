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


def forward_facing(c2w: np.ndarray, max_angle_deg: float = 60.0) -> bool:
    """True when every camera of ``c2w`` (M, 4, 4) looks within ``max_angle_deg`` of the cameras' mean viewing
    direction (an LLFF-style forward-facing capture, where an orbit would look at the scene from behind)."""
    fwd = c2w[:, :3, 2]
    mean = fwd.mean(axis=0)
    norm = np.linalg.norm(mean)
    if norm < 1e-9:
        return False
    cos = fwd @ (mean / norm) / np.maximum(np.linalg.norm(fwd, axis=1), 1e-12)
    return bool(np.all(cos >= np.cos(np.radians(max_angle_deg))))


def _look_at(c: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    z = target - c
    z /= max(np.linalg.norm(z), 1e-12)
    x = np.cross(z, up)
    x /= max(np.linalg.norm(x), 1e-12)
    y = np.cross(z, x)
    out = np.eye(4)
    out[:3, :3] = np.stack([x, y, z], axis=1)
    out[:3, 3] = c
    return out


def ellipse_cameras(c2w: np.ndarray, n: int) -> np.ndarray:
    """(n, 4, 4) cameras of a forward-facing capture (LLFF's render path, flat): centres on an ellipse around the
    training cameras' mean centre, in the plane across their mean viewing direction, with semi-axes the 90th
    percentile of the training centres' offsets along each axis of that plane; all look at the point closest to the
    training cameras' optical axes (or one unit ahead when that point lies behind them)."""
    centres, fwd = c2w[:, :3, 3], c2w[:, :3, 2]
    mean_c = centres.mean(axis=0)
    d = fwd.mean(axis=0)
    d /= max(np.linalg.norm(d), 1e-12)
    a = np.zeros((3, 3))
    b = np.zeros(3)
    for c, f in zip(centres, fwd, strict=True):
        proj = np.eye(3) - np.outer(f, f)
        a += proj
        b += proj @ c
    target = np.linalg.lstsq(a + 1e-9 * np.eye(3), b, rcond=None)[0]
    depth = float((target - mean_c) @ d)
    if not np.isfinite(depth) or depth <= 1e-6:
        depth = 1.0
    target = mean_c + depth * d
    up = -c2w[:, :3, 1].mean(axis=0)
    up -= (up @ d) * d
    if np.linalg.norm(up) < 1e-9:
        up = np.cross(d, [1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.cross(d, [0.0, 1.0, 0.0])
    up /= np.linalg.norm(up)
    e1 = np.cross(up, d)
    rel = centres - mean_c
    r1 = float(np.percentile(np.abs(rel @ e1), 90))
    r2 = float(np.percentile(np.abs(rel @ up), 90))
    out = np.zeros((n, 4, 4))
    for i, phi in enumerate(np.linspace(0.0, 2 * np.pi, n, endpoint=False)):
        out[i] = _look_at(mean_c + r1 * np.cos(phi) * e1 + r2 * np.sin(phi) * up, target, up)
    return out


def render_path(c2w: np.ndarray, n: int) -> tuple[np.ndarray, str]:
    """A path of ``n`` cameras around a capture: :func:`ellipse_cameras` for forward-facing captures, else
    :func:`orbit_cameras`. Returns the (n, 4, 4) cameras and the kind (``ellipse`` or ``orbit``)."""
    if forward_facing(c2w):
        return ellipse_cameras(c2w, n), "ellipse"
    return orbit_cameras(c2w, n), "orbit"
