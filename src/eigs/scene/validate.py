"""Validation of a scene (version 2), on write and on read.

Each check raises :class:`EigsError` naming the file and the problem. Event arrays are checked in chunks so
validating 100 M events needs little extra memory.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np

from eigs.errors import EigsError
from eigs.scene.model import CAMERA_RESPONSES, POSE_SOURCES, SHARP_KINDS, Events, Scene

EVENT_CHUNK = 8_000_000
RIGID_TOL = 1e-5  # max |RᵀR − I| and |det R − 1| accepted for a rotation block


def _finite(path: str, name: str, a: np.ndarray) -> None:
    if a.dtype.kind == "f" and not np.all(np.isfinite(a)):
        bad = int(np.count_nonzero(~np.isfinite(a)))
        raise EigsError(path, f"{name} has {bad} NaN/Inf value(s)")


def _shape(path: str, name: str, a: np.ndarray, shape: tuple) -> None:
    """``shape`` entries that are None match anything."""
    if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape, strict=True)):
        want = "×".join("?" if s is None else str(s) for s in shape)
        raise EigsError(path, f"{name} has shape {'×'.join(map(str, a.shape))}, expected {want}")


def _dtype(path: str, name: str, a: np.ndarray, dtype: type) -> None:
    if a.dtype != np.dtype(dtype):
        raise EigsError(path, f"{name} has dtype {a.dtype}, expected {np.dtype(dtype)}")


def check_rigid(path: str, name: str, m: np.ndarray) -> None:
    """``m``: (..., 4, 4) camera-to-world matrices: finite, rotation block orthonormal with det +1, last row 0 0 0 1."""
    _finite(path, name, m)
    if m.shape[-2:] != (4, 4):
        raise EigsError(path, f"{name} must hold 4×4 matrices, got shape {m.shape}")
    flat = m.reshape(-1, 4, 4)
    if flat.shape[0] == 0:
        return
    if not np.allclose(flat[:, 3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise EigsError(path, f"{name}: last row of a pose is not [0 0 0 1]")
    r = flat[:, :3, :3].astype(np.float64)
    ortho = np.abs(np.einsum("nji,njk->nik", r, r) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(r)
    bad = np.flatnonzero((ortho > RIGID_TOL) | (np.abs(det - 1.0) > RIGID_TOL))
    if bad.size:
        i = int(bad[0])
        raise EigsError(
            path,
            f"{name}: {bad.size} pose(s) are not rigid (first at index {i}: "
            f"|RᵀR−I| = {ortho[i]:.2e}, det R = {det[i]:.6f})",
        )


def _chunks(n: int) -> Iterator[slice]:
    for s in range(0, n, EVENT_CHUNK):
        yield slice(s, min(n, s + EVENT_CHUNK))


def check_event_chunk(
    path: str,
    x: np.ndarray,
    y: np.ndarray,
    t: np.ndarray,
    p: np.ndarray,
    width: int,
    height: int,
    last_t: int | None,
) -> int | None:
    """Check one chunk of raw events; returns the chunk's last timestamp (for the sortedness check across chunks)."""
    n = t.shape[0]
    for name, a in (("events/x", x), ("events/y", y), ("events/p", p)):
        if a.shape != (n,):
            raise EigsError(path, f"{name} has {a.shape[0]} entries but events/t has {n}")
    if n == 0:
        return last_t
    if x.max() >= width or y.max() >= height:
        raise EigsError(
            path,
            f"event coordinates outside the {width}×{height} sensor (max x = {int(x.max())}, "
            f"max y = {int(y.max())})",
        )
    if t[0] < 0 and last_t is None:
        raise EigsError(path, f"events/t has negative timestamps (first {int(t[0])} µs)")
    if (last_t is not None and t[0] < last_t) or np.any(t[1:] < t[:-1]):
        raise EigsError(path, "events/t is not sorted in time (timestamps go backwards)")
    bad = (p != 1) & (p != -1)
    if np.any(bad):
        raise EigsError(path, f"events/p must be ±1; found {sorted(set(np.unique(p[bad]).tolist()))[:5]}")
    return int(t[-1])


def _view_index_ranges(path: str, vi: np.ndarray, n: int, n_views: int) -> None:
    _dtype(path, "events/view_index", vi, np.int64)
    _shape(path, "events/view_index", vi, (n_views, 2))
    if np.any(vi < 0) or np.any(vi > n) or np.any(vi[:, 1] < vi[:, 0]):
        raise EigsError(path, f"events/view_index has offsets outside [0, {n}] or stop < start")


def check_view_index_sorted(
    path: str, vi: np.ndarray, n: int, t: Any, exposure_us: np.ndarray | None, n_views: int
) -> None:
    """:func:`check_view_index` for a stream too large to hold: ``t`` (N,) sorted timestamps that are only indexed
    (an HDF5 dataset will do) at the 2V offsets' neighbours. With t sorted, offset k is the first event at or after
    time b exactly when t[k − 1] < b ≤ t[k] (each side where it exists)."""
    _view_index_ranges(path, vi, n, n_views)
    if exposure_us is None:
        return
    k = vi.reshape(-1)
    b = np.asarray(exposure_us, np.int64).reshape(-1)
    idx = np.unique(np.concatenate([k[k > 0] - 1, k[k < n]]))
    vals = np.asarray(t[idx] if idx.size else np.zeros(0, np.int64), np.int64)
    at = dict(zip(idx.tolist(), vals.tolist(), strict=True))
    for j in range(k.shape[0]):
        kj, bj = int(k[j]), int(b[j])
        if (kj > 0 and at[kj - 1] >= bj) or (kj < n and at[kj] < bj):
            v, side = divmod(j, 2)
            raise EigsError(
                path,
                f"events/view_index does not cover the events of view {v}'s exposure "
                f"[{exposure_us[v, 0]}, {exposure_us[v, 1]}) µs: has [{vi[v, 0]}, {vi[v, 1]}), whose "
                f"{'start' if side == 0 else 'stop'} {kj} is not the first event at or after {bj} µs",
            )


def check_view_index(path: str, events: Events, exposure_us: np.ndarray | None, n_views: int) -> None:
    """``view_index`` (V, 2) must be non-decreasing offsets in [0, N]; with known exposures it must equal exactly
    the events with start ≤ t < end of each view (:func:`check_view_index_sorted` on the events in memory)."""
    if events.view_index is not None:
        check_view_index_sorted(path, events.view_index, len(events), events.t, exposure_us, n_views)


def validate_header(path: str, scene: Scene) -> None:
    """Everything but the raw event arrays."""
    cam = scene.camera
    _shape(path, "camera/K", cam.K, (3, 3))
    _finite(path, "camera/K", cam.K)
    fx, fy = cam.K[0, 0], cam.K[1, 1]
    if not (fx > 0 and fy > 0) or not np.allclose(cam.K[2], [0, 0, 1]) or cam.K[1, 0] != 0:
        raise EigsError(path, f"camera/K is not a pinhole intrinsic matrix: {cam.K.tolist()}")
    if cam.width <= 0 or cam.height <= 0:
        raise EigsError(path, f"camera size must be positive, got {cam.width}×{cam.height}")
    _shape(path, "camera/distortion", cam.distortion, (5,))
    _finite(path, "camera/distortion", cam.distortion)
    if scene.channels not in (1, 3):
        raise EigsError(path, f"channels must be 1 or 3, got {scene.channels}")
    if scene.camera_response not in CAMERA_RESPONSES:
        raise EigsError(
            path, f"camera_response must be one of {CAMERA_RESPONSES}, got {scene.camera_response!r}"
        )
    if scene.background is not None:
        bg = np.asarray(scene.background, dtype=np.float64)
        _shape(path, "background", bg, (scene.channels,))
        _finite(path, "background", bg)
        if np.any(bg < 0) or np.any(bg > 1):
            raise EigsError(path, f"background must lie in [0, 1], got {bg.tolist()}")
    if scene.contrast_threshold is not None and not (
        np.isfinite(scene.contrast_threshold) and scene.contrast_threshold > 0
    ):
        raise EigsError(path, f"contrast_threshold must be a positive number, got {scene.contrast_threshold}")

    h, w, c = cam.height, cam.width, scene.channels
    n_views = scene.n_views
    if scene.frames is not None:
        f = scene.frames
        _dtype(path, "frames/blurry", f.blurry, np.uint8)
        _shape(path, "frames/blurry", f.blurry, (None, h, w, c))
        if f.exposure_us is not None:
            _dtype(path, "frames/exposure_us", f.exposure_us, np.int64)
            _shape(path, "frames/exposure_us", f.exposure_us, (f.n_views, 2))
            bad = np.flatnonzero(f.exposure_us[:, 1] < f.exposure_us[:, 0])
            if bad.size:
                v = int(bad[0])
                raise EigsError(
                    path,
                    f"frames/exposure_us: view {v} ends ({f.exposure_us[v, 1]} µs) before it starts "
                    f"({f.exposure_us[v, 0]} µs)",
                )
        if f.t_us is not None:
            if f.exposure_us is not None:
                raise EigsError(path, "frames/t_us is for frames without exposure windows, but exposure_us is set too")
            _dtype(path, "frames/t_us", f.t_us, np.int64)
            _shape(path, "frames/t_us", f.t_us, (f.n_views,))
        if f.names is not None:
            if len(f.names) != f.n_views or not all(isinstance(n, str) and n for n in f.names):
                raise EigsError(path, f"frames/names must hold one non-empty name per frame ({f.n_views})")
            if len(set(f.names)) != len(f.names):
                raise EigsError(path, "frames/names must be unique")
    if scene.binned is not None:
        b = scene.binned
        _dtype(path, "events/binned", b.counts, np.int32)
        _shape(path, "events/binned", b.counts, (n_views, None, h, w))
        _dtype(path, "events/bin_edges_us", b.bin_edges_us, np.int64)
        _shape(path, "events/bin_edges_us", b.bin_edges_us, (n_views, b.n_bins + 1))
        if np.any(np.diff(b.bin_edges_us, axis=1) <= 0):
            raise EigsError(path, "events/bin_edges_us must be strictly increasing within each view")
    if scene.poses is not None:
        ps = scene.poses
        if ps.source not in POSE_SOURCES:
            raise EigsError(path, f"poses source must be one of {POSE_SOURCES}, got {ps.source!r}")
        _shape(path, "poses/latent_c2w", ps.latent_c2w, (n_views, None, 4, 4))
        check_rigid(path, "poses/latent_c2w", ps.latent_c2w)
        _dtype(path, "poses/latent_t_us", ps.latent_t_us, np.int64)
        _shape(path, "poses/latent_t_us", ps.latent_t_us, ps.latent_c2w.shape[:2])
        if np.any(np.diff(ps.latent_t_us, axis=1) < 0):
            raise EigsError(path, "poses/latent_t_us must be non-decreasing within each view")
    if scene.trajectory is not None:
        tr = scene.trajectory
        _dtype(path, "gt/trajectory/t_us", tr.t_us, np.int64)
        _shape(path, "gt/trajectory/c2w", tr.c2w, (tr.t_us.shape[0], 4, 4))
        if np.any(np.diff(tr.t_us) <= 0):
            raise EigsError(path, "gt/trajectory/t_us must be strictly increasing")
        check_rigid(path, "gt/trajectory/c2w", tr.c2w)
    if scene.sharp is not None:
        s = scene.sharp
        _dtype(path, "gt/sharp/images", s.images, np.uint8)
        _shape(path, "gt/sharp/images", s.images, (None, h, w, c))
        n = s.images.shape[0]
        _shape(path, "gt/sharp/c2w", s.c2w, (n, 4, 4))
        check_rigid(path, "gt/sharp/c2w", s.c2w)
        for name, a in (("gt/sharp/t_us", s.t_us), ("gt/sharp/view", s.view)):
            _dtype(path, name, a, np.int64)
            _shape(path, name, a, (n,))
        _dtype(path, "gt/sharp/kind", s.kind, np.uint8)
        _shape(path, "gt/sharp/kind", s.kind, (n,))
        if not np.all(np.isin(s.kind, list(SHARP_KINDS))):
            raise EigsError(path, f"gt/sharp/kind must be one of {sorted(SHARP_KINDS)}")
        if np.any(s.view < -1) or np.any(s.view >= max(n_views, 0)) and n_views > 0:
            raise EigsError(path, f"gt/sharp/view must be −1 or a view index below {n_views}")


def check_event_dtypes(path: str, ev: Events) -> None:
    """x, y uint16; t int64; p int8 (no silent conversion of, e.g., float seconds)."""
    for name, a, dt in (
        ("events/x", ev.x, np.uint16),
        ("events/y", ev.y, np.uint16),
        ("events/t", ev.t, np.int64),
        ("events/p", ev.p, np.int8),
    ):
        _dtype(path, name, a, dt)


def validate_events(path: str, scene: Scene) -> None:
    """The raw event arrays and their view index (chunked)."""
    ev = scene.events
    if ev is None:
        return
    check_event_dtypes(path, ev)
    last = None
    for sl in _chunks(len(ev)):
        last = check_event_chunk(
            path, ev.x[sl], ev.y[sl], ev.t[sl], ev.p[sl], scene.camera.width, scene.camera.height, last
        )
    if ev.view_index is not None:
        exposure = scene.frames.exposure_us if scene.frames is not None else None
        check_view_index(path, ev, exposure, ev.view_index.shape[0] if scene.n_views == 0 else scene.n_views)


def validate(path: str, scene: Scene) -> None:
    """Full validation of ``scene`` (as written to / read from ``path``)."""
    validate_header(path, scene)
    validate_events(path, scene)
