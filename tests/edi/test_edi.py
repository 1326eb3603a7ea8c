"""EDI: E²NeRF mode vs an independent float64 evaluation, the exact exposure integral vs a slow reference,
zero events, sharp-view skip, mode selection, clear errors, and finiteness under extreme inputs (hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eigs.edi.edi import (
    ExposureIntegral,
    edi_continuous,
    edi_discrete,
    edi_e2nerf,
)
from eigs.edi.pipeline import EdiOptions, compute_edi, resolve_mode
from eigs.errors import EigsError
from eigs.scene import BinnedEvents, Camera, Events, Frames, Scene


def _e2nerf_reference(blur_255: np.ndarray, bins: np.ndarray, c: float = 0.3) -> np.ndarray:
    """The formula of the issue, evaluated naively in float64: S_0 = 0, S_k = Σ_{i≤k} B_i, D = Σ exp(c S_k),
    I_0 = min(255, (B+1) I / D), I_k = I_0 exp(c S_k)."""
    b = bins.shape[0]
    s = [np.zeros(bins.shape[1:])]
    for i in range(b):
        s.append(s[-1] + bins[i].astype(np.float64))
    d = sum(np.exp(c * sk) for sk in s)
    i0 = np.minimum(255.0, (b + 1) * blur_255.astype(np.float64) / d[..., None])
    return np.stack([i0 * np.exp(c * sk)[..., None] for sk in s])


def _scene(blurry, events=None, binned=None, exposure=None, source="", response="linear", t_us=None):
    v, h, w, ch = blurry.shape
    return Scene(
        name="t",
        camera=Camera(K=np.array([[w, 0, w / 2], [0, w, h / 2], [0, 0, 1.0]]), width=w, height=h),
        channels=ch,
        camera_response=response,
        source=source,
        frames=Frames(blurry, exposure, t_us),
        events=events,
        binned=binned,
    )


def test_e2nerf_matches_float64_reference():
    rng = np.random.default_rng(0)
    h, w = 20, 30
    blur = rng.integers(0, 256, size=(h, w, 3)).astype(np.uint8)
    blur[0, :] = 0
    blur[1, :] = 255
    bins = rng.integers(-6, 7, size=(4, h, w)).astype(np.int32)
    cum = np.concatenate([np.zeros((1, h, w), np.int64), np.cumsum(bins, axis=0)])
    ref = _e2nerf_reference(blur, bins)
    got = edi_e2nerf(blur, cum)
    stored = lambda a: np.clip(a, 0, 255) / 255.0  # noqa: E731
    assert np.abs(stored(got) - stored(ref)).max() < 1e-4
    np.testing.assert_allclose(got, ref, rtol=1e-12, atol=1e-9)  # also before storage clipping

    # through the whole stage, from E²NeRF-style pre-binned events (mode auto → e2nerf)
    blurry = np.stack([blur, blur[::-1]])
    counts = np.stack([bins, -bins])
    edges = np.array([[0, 10, 20, 30, 40], [100, 110, 120, 130, 140]], np.int64)
    scene = _scene(blurry, binned=BinnedEvents(counts, edges), source="e2nerf-real:/x")
    res = compute_edi(scene, EdiOptions(show_progress=False))
    assert res.mode == "e2nerf" and res.n_bins == 4 and np.all(res.threshold == 0.3)
    for v in range(2):
        ref_v = _e2nerf_reference(blurry[v], counts[v])
        assert np.abs(res.latent[v] - stored(ref_v)).max() < 1e-4
    np.testing.assert_array_equal(res.timestamps_us, edges)
    with pytest.raises(EigsError, match="pre-binned into 4 bins"):
        compute_edi(scene, EdiOptions(bins=8, show_progress=False))


def test_exposure_integral_matches_slow_reference():
    rng = np.random.default_rng(1)
    h, w, n = 3, 4, 400
    start, end, t_ref = 1000, 2000, 1250
    t = np.sort(rng.integers(900, 2100, size=n)).astype(np.int64)
    t[10:14] = t[10]  # simultaneous events
    x = rng.integers(0, w, size=n)
    y = rng.integers(0, h, size=n)
    p = rng.choice([-1, 1], size=n)
    for c in (0.0, 0.2, 0.7):
        got = ExposureIntegral(x, y, t, p, start, end, t_ref, h, w).log_mean_exp(c)
        ref = np.zeros((h, w))
        for i in range(h):
            for j in range(w):
                sel = (x == j) & (y == i) & (t >= start) & (t < end)
                ts, ps = t[sel], p[sel]
                grid = np.arange(start, end) + 0.5  # 1 µs steps: E is constant on each step
                e = np.array([ps[ts < g].sum() for g in grid]) - ps[ts < t_ref].sum()
                ref[i, j] = np.log(np.mean(np.exp(c * e)))
        np.testing.assert_allclose(got, ref, atol=1e-12)


def test_continuous_edi_recovers_exact_latent():
    """A pixel whose log intensity steps by exactly C at each event: the double integral is exact."""
    c, eps = 0.25, 1e-3
    start, end = 0, 1000
    t_ev = np.array([100, 300, 350, 800], np.int64)
    p_ev = np.array([1, 1, -1, 1])
    y0 = 0.3  # intensity at the start
    grid = np.arange(start, end) + 0.5
    e_abs = np.array([p_ev[t_ev < g].sum() for g in grid])
    blur = np.mean((y0 + eps) * np.exp(c * e_abs)) - eps
    integ = ExposureIntegral(np.zeros(4), np.zeros(4), t_ev, p_ev, start, end, start, 1, 1)
    times = np.array([0, 250, 500, 750, 999])
    cum = np.array([p_ev[t_ev < tk].sum() for tk in times]).reshape(5, 1, 1)
    lat = edi_continuous(np.full((1, 1, 1), blur), cum, integ.log_mean_exp(c), c, eps)
    np.testing.assert_allclose(lat[:, 0, 0, 0], (y0 + eps) * np.exp(c * cum[:, 0, 0]) - eps, rtol=1e-12)


def test_zero_events_give_the_blurry_frame():
    rng = np.random.default_rng(2)
    blur = rng.integers(0, 256, size=(2, 6, 8, 3)).astype(np.uint8)
    cum = np.zeros((5, 6, 8), np.int32)
    np.testing.assert_allclose(edi_e2nerf(blur[0], cum), np.broadcast_to(blur[0], (5, 6, 8, 3)), atol=1e-12)
    lin = blur[0] / 255.0
    np.testing.assert_allclose(edi_discrete(lin, cum, 0.2), np.broadcast_to(lin, (5, 6, 8, 3)), atol=1e-12)
    exposure = np.array([[0, 1000], [2000, 3000]], np.int64)
    for response in ("linear", "srgb"):
        scene = _scene(blur, events=Events.empty(), exposure=exposure, response=response)
        scene.events.view_index = np.zeros((2, 2), np.int64)
        res = compute_edi(scene, EdiOptions(show_progress=False))
        assert res.sharp.all() and res.mode == "estimated"
        np.testing.assert_allclose(res.latent, np.broadcast_to(blur[:, None] / 255.0, res.latent.shape), atol=1e-6)
        np.testing.assert_array_equal(res.timestamps_us[:, [0, -1]], exposure)


def test_instantaneous_frames_pass_through_at_their_timestamps():
    """Frames with timestamps and no exposure windows are instants: no event lies inside them, so every view is
    passed through unchanged, every latent time is the frame's timestamp; raw events elsewhere do not matter."""
    rng = np.random.default_rng(4)
    blur = rng.integers(0, 256, size=(3, 6, 8, 1)).astype(np.uint8)
    t_us = np.array([0, 38_766, 77_531], np.int64)
    n = 300
    t = np.sort(rng.integers(0, 80_000, n)).astype(np.int64)
    ev = Events(rng.integers(0, 8, n).astype(np.uint16), rng.integers(0, 6, n).astype(np.uint16), t,
                rng.choice(np.array([-1, 1], np.int8), n))
    for events in (None, ev):
        res = compute_edi(_scene(blur, events=events, t_us=t_us), EdiOptions(bins=4, show_progress=False))
        assert res.sharp.all() and res.event_count.tolist() == [0, 0, 0]
        np.testing.assert_array_equal(res.timestamps_us, np.repeat(t_us[:, None], 5, axis=1))
        np.testing.assert_allclose(res.latent, np.broadcast_to(blur[:, None] / 255.0, res.latent.shape), atol=1e-6)


def test_sparse_view_is_marked_sharp_and_copied():
    rng = np.random.default_rng(3)
    h, w = 20, 20
    blur = rng.integers(0, 256, size=(2, h, w, 1)).astype(np.uint8)
    exposure = np.array([[0, 1000], [2000, 3000]], np.int64)
    # view 0: 3 events (< 0.01 per pixel = 4); view 1: 400 events
    t = np.concatenate([[10, 20, 30], np.sort(rng.integers(2000, 3000, 400))]).astype(np.int64)
    x = rng.integers(0, w, t.size).astype(np.uint16)
    y = rng.integers(0, h, t.size).astype(np.uint16)
    p = rng.choice(np.array([-1, 1], np.int8), t.size)
    ev = Events(x, y, t, p, np.array([[0, 3], [3, 403]], np.int64))
    res = compute_edi(_scene(blur, events=ev, exposure=exposure), EdiOptions(threshold=0.2, show_progress=False))
    assert res.sharp.tolist() == [True, False]
    assert res.event_count.tolist() == [3, 400]
    np.testing.assert_allclose(res.events_per_pixel, [3 / 400, 1.0])
    np.testing.assert_allclose(res.latent[0], np.broadcast_to(blur[0] / 255.0, res.latent[0].shape), atol=1e-6)
    assert not np.allclose(res.latent[1, 0], blur[1] / 255.0, atol=1e-3)
    assert res.threshold_scope == "given"


def test_errors_and_mode_selection():
    blur = np.zeros((1, 4, 4, 1), np.uint8)
    ev = Events(np.zeros(1, np.uint16), np.zeros(1, np.uint16), np.zeros(1, np.int64), np.ones(1, np.int8))
    with pytest.raises(EigsError, match="--exposure-us"):
        compute_edi(_scene(blur, events=ev), EdiOptions(show_progress=False))
    assert resolve_mode(_scene(blur, source="e2nerf-synthetic:/d"), "auto") == "e2nerf"
    assert resolve_mode(_scene(blur, source="e2nerf-real:/d"), "auto") == "e2nerf"
    # a built-in scene with E²NeRF's blur synthesis has our simulator's events: the estimated threshold, not c = 0.3
    assert resolve_mode(_scene(blur, source="eigs synth --scene chair (seed 0, blur e2nerf)"), "auto") == "estimated"
    assert resolve_mode(_scene(blur, source="aedat4:/d"), "auto") == "estimated"
    assert resolve_mode(_scene(blur, source="aedat4:/d"), "e2nerf") == "e2nerf"
    with pytest.raises(EigsError, match="--mode"):
        resolve_mode(_scene(blur), "fast")


counts_st = st.integers(min_value=-(10**6), max_value=10**6)


@settings(max_examples=60, deadline=None)
@given(
    s=st.lists(counts_st, min_size=4, max_size=4),
    pix=st.sampled_from([0, 1, 128, 254, 255]),
    c=st.floats(min_value=0.0, max_value=1.0),
)
def test_extreme_counts_stay_finite(s, pix, c):
    bins = np.array(s, np.int64).reshape(4, 1, 1)
    cum = np.concatenate([np.zeros((1, 1, 1), np.int64), np.cumsum(bins, axis=0)])
    blur = np.full((1, 1, 3), pix, np.uint8)
    out = edi_e2nerf(blur, cum, 0.3 if c == 0 else c)
    assert np.all(np.isfinite(out)) and np.all(out >= 0) and out[0].max() <= 255
    lin = edi_discrete(blur / 255.0, cum, c)
    assert np.all(np.isfinite(lin))
    # the continuous integral with huge counts piled on few timestamps
    n = 200
    t = np.sort(np.random.default_rng(abs(s[0]) % 97).integers(0, 1000, n)).astype(np.int64)
    p = np.where(np.arange(n) < n // 2, np.sign(s[1]) or 1, np.sign(s[2]) or -1)
    integ = ExposureIntegral(np.zeros(n), np.zeros(n), t, p, 0, 1000, 0, 1, 1)
    lm = integ.log_mean_exp(c * 1000.0)  # |c·E| up to 1e5
    assert np.all(np.isfinite(lm))
    big = np.array([0, s[0], s[1], s[2], s[3]]).reshape(5, 1, 1)
    out2 = edi_continuous(blur / 255.0, big, lm, c * 1000.0)
    assert np.all(np.isfinite(out2))
