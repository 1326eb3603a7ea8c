"""EDI under extreme counts, thresholds from 0.01 to 2, and black or saturated pixels.

Extends tests/edi/test_edi.py (whose hypothesis test checks finiteness for c ≤ 1): here every mode is checked
against an independent evaluation — E²NeRF's formula as ratios of sums evaluated per frame, the blur-formation
identity (the latent frames average back to the blurry frame), and a brute-force exposure integral over every
microsecond — and the whole stage must produce a valid artifact.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from eigs.artifacts.edi import read_edi, write_edi
from eigs.edi.edi import ExposureIntegral, edi_continuous, edi_discrete, edi_e2nerf
from eigs.edi.pipeline import EdiOptions, compute_edi
from eigs.scene import BinnedEvents, Camera, Events, Frames, Scene
from tests.stress.budget import stress

THRESHOLDS = st.floats(min_value=0.01, max_value=2.0, allow_nan=False)
PIXELS = st.sampled_from([0, 1, 2, 127, 128, 253, 254, 255])
BIN_COUNTS = st.integers(min_value=-20_000, max_value=20_000)


def _e2nerf_ratio_reference(blur: int, cum: list[int], c: float) -> list[float]:
    """Stored value (clip to [0, 255], / 255) of E²NeRF's I_k = min(255, n·I/D)·exp(c·S_k), D = Σ_j exp(c·S_j),
    in plain Python floats: unclamped, I_k = n·I / Σ_j exp(c·(S_j − S_k)) (each term shifted by S_k, so the sum
    overflows only when I_k underflows to 0); clamped (n·I/D ≥ 255), I_k = 255·exp(c·S_k)."""
    n = len(cum)
    s = [c * v for v in cum]
    m = max(s)
    log_d = m + math.log(math.fsum(math.exp(v - m) for v in s))
    out = []
    clamped = blur > 0 and math.log(n * blur) - log_d >= math.log(255.0)
    for sk in s:
        if clamped:
            val = 255.0 * math.exp(min(sk, 0.0))  # ≥ 255 for sk ≥ 0: stored as 255
        else:
            terms = [sj - sk for sj in s]
            den = math.inf if max(terms) > 700 else math.fsum(math.exp(t) for t in terms)
            val = n * blur / den
        out.append(min(max(val, 0.0), 255.0) / 255.0)
    return out


@stress(60)
@given(bins=st.lists(BIN_COUNTS, min_size=1, max_size=6), c=THRESHOLDS, pix=PIXELS)
@example(bins=[351], c=2.0, pix=1)  # regression: c·S = 702 > EXP_CLIP gave 2·e⁻² instead of 2 (exp clipped, 1/D not)
@example(bins=[10_000, -3], c=0.3, pix=200)  # a hot pixel: the bright frame was returned black (0·exp(700))
def test_e2nerf_mode_matches_the_ratio_reference(bins, c, pix):
    cum = [0, *np.cumsum(bins).tolist()]
    got = edi_e2nerf(np.full((1, 1, 3), pix, np.uint8), np.array(cum, np.int64).reshape(-1, 1, 1), c)
    assert np.all(np.isfinite(got)) and np.all(got >= 0)
    stored = np.clip(got[:, 0, 0, 0], 0.0, 255.0) / 255.0
    ref = _e2nerf_ratio_reference(pix, cum, c)
    np.testing.assert_allclose(stored, ref, rtol=1e-9, atol=1e-12)
    if pix < 255 and max(ref) < 1.0:  # unclamped: the frames average back to the blurry value
        assert abs(np.mean(got[:, 0, 0, 0]) - pix) <= 1e-9 * max(pix, 1)


@stress(60)
@given(bins=st.lists(BIN_COUNTS, min_size=1, max_size=6), c=THRESHOLDS, pix=PIXELS, srgb=st.booleans())
def test_discrete_estimated_frames_average_back_to_the_blurry_frame(bins, c, pix, srgb):
    from eigs.edi.edi import LOG_EPS, to_linear

    cum = np.array([0, *np.cumsum(bins).tolist()], np.int64).reshape(-1, 1, 1)
    lin = to_linear(np.full((1, 1, 1), pix, np.uint8), "srgb" if srgb else "linear")
    got = edi_discrete(lin, cum, c)
    assert np.all(np.isfinite(got)) and np.all(got >= -LOG_EPS * (1 + 1e-12))
    # (1/L) Σ_k (Y_k + ε) = Y_blur + ε: the model's blur formation, for any counts and threshold
    mean = float(np.mean(got[:, 0, 0, 0] + LOG_EPS))
    assert abs(mean - (float(lin[0, 0, 0]) + LOG_EPS)) <= 1e-12 * (float(lin[0, 0, 0]) + LOG_EPS) * len(cum)


@st.composite
def _bursts(draw):
    """Events of one pixel in [0, 200) µs: a few bursts of up to 5,000 same-polarity events at one timestamp."""
    n_bursts = draw(st.integers(1, 5))
    t = draw(st.lists(st.integers(-20, 219), min_size=n_bursts, max_size=n_bursts))
    size = draw(st.lists(st.integers(1, 5000), min_size=n_bursts, max_size=n_bursts))
    pol = draw(st.lists(st.sampled_from([-1, 1]), min_size=n_bursts, max_size=n_bursts))
    ts = np.repeat(np.array(t, np.int64), size)
    ps = np.repeat(np.array(pol, np.int64), size)
    order = np.argsort(ts, kind="stable")
    return ts[order], ps[order]


@stress(40)
@given(ev=_bursts(), c=THRESHOLDS, t_ref=st.integers(0, 199), pix=PIXELS)
def test_exposure_integral_matches_a_per_microsecond_sum(ev, c, t_ref, pix):
    t, p = ev
    start, end = 0, 200
    integ = ExposureIntegral(np.zeros(len(t)), np.zeros(len(t)), t, p, start, end, t_ref, 1, 1)
    got = float(integ.log_mean_exp(c)[0, 0])
    # brute force: E is constant on each 1 µs step [u, u + 1); an event at u counts from u on
    inside = (t >= start) & (t < end)
    ti, pi = t[inside], p[inside]
    e = np.array([pi[ti <= u].sum() for u in range(start, end)], np.float64) - pi[ti < t_ref].sum()
    a = c * e
    ref = float(a.max() + np.log(np.mean(np.exp(a - a.max()))))
    assert math.isfinite(got) and abs(got - ref) <= 1e-9 * max(1.0, abs(ref))
    # the continuous latent frames average (over the exposure, weighted) back to the blurry frame
    lin = np.full((1, 1, 1), pix / 255.0)
    lat = edi_continuous(lin, e.reshape(-1, 1, 1), integ.log_mean_exp(c), c)
    assert np.all(np.isfinite(lat))
    from eigs.edi.edi import LOG_EPS

    assert abs(np.mean(lat[:, 0, 0, 0] + LOG_EPS) - (pix / 255.0 + LOG_EPS)) <= 1e-9 * (pix / 255.0 + LOG_EPS)


def _scene(blurry: np.ndarray, **kw) -> Scene:
    v, h, w, ch = blurry.shape
    return Scene(
        name="stress",
        camera=Camera(K=np.array([[w, 0, w / 2], [0, w, h / 2], [0, 0, 1.0]]), width=w, height=h),
        channels=ch,
        camera_response=kw.pop("response", "linear"),
        source=kw.pop("source", ""),
        frames=Frames(blurry, kw.pop("exposure", None)),
        **kw,
    )


def _frames(pix: int, h: int = 6, w: int = 8) -> np.ndarray:
    """Two RGB views: the left half ``pix`` (black or saturated), the right half a ramp."""
    ramp = np.linspace(10, 245, w // 2).round().astype(np.uint8)
    img = np.empty((h, w, 3), np.uint8)
    img[:, : w // 2] = pix
    img[:, w // 2 :] = ramp[None, :, None]
    return np.stack([img, img[::-1]])


@stress(15)
@given(pix=st.sampled_from([0, 255]), c=THRESHOLDS, big=st.integers(100, 30_000), seed=st.integers(0, 2**16))
def test_e2nerf_stage_with_extreme_prebinned_counts(tmp_path_factory, pix, c, big, seed):
    rng = np.random.default_rng(seed)
    blurry = _frames(pix)
    counts = rng.integers(-3, 4, size=(2, 4, 6, 8)).astype(np.int32)
    counts[:, rng.integers(0, 4), 0, 0] = big * rng.choice([-1, 1])  # a hot pixel in the black/saturated half
    counts[:, :, 5, 7] = big  # and one in the ramp
    edges = np.array([[0, 10, 20, 30, 40], [100, 110, 120, 130, 140]], np.int64)
    scene = _scene(blurry, binned=BinnedEvents(counts, edges), source="e2nerf-real:/x")
    res = compute_edi(scene, EdiOptions(threshold=c, show_progress=False))
    assert res.mode == "e2nerf"
    assert np.all(np.isfinite(res.latent)) and res.latent.min() >= 0 and res.latent.max() <= 1
    cum = res.cum_counts.astype(np.int64)
    for v in range(2):
        for i, j in ((0, 0), (5, 7), (2, 1)):
            ref = _e2nerf_ratio_reference(int(blurry[v, i, j, 0]), cum[v, :, i, j].tolist(), c)
            np.testing.assert_allclose(res.latent[v, :, i, j, 0], ref, atol=1e-6)
    path = tmp_path_factory.mktemp("edi") / "edi.h5"
    write_edi(res, path)
    back = read_edi(path)
    np.testing.assert_array_equal(back.latent, res.latent)


@stress(12)
@given(
    pix=st.sampled_from([0, 255]),
    c=THRESHOLDS,
    burst=st.integers(1, 3000),
    per_pixel=st.booleans(),
    response=st.sampled_from(["linear", "srgb"]),
)
def test_estimated_stage_with_bursts_black_and_saturated(pix, c, burst, per_pixel, response):
    rng = np.random.default_rng(burst)
    h, w = 6, 8
    blurry = _frames(pix, h, w)
    exposure = np.array([[0, 1000], [2000, 3000]], np.int64)
    n = 400
    t = np.sort(rng.integers(0, 3000, n)).astype(np.int64)
    x, y = rng.integers(0, w, n), rng.integers(0, h, n)
    p = rng.choice([-1, 1], n)
    # a burst of `burst` ON events at one instant on a black/saturated pixel and at a ramp pixel, in each view
    tb = np.repeat(np.array([500, 2500], np.int64), burst)
    t = np.concatenate([t, tb, tb + 1])
    x = np.concatenate([x, np.zeros(2 * burst, int), np.full(2 * burst, w - 1)])
    y = np.concatenate([y, np.zeros(2 * burst, int), np.full(2 * burst, h - 1)])
    p = np.concatenate([p, np.ones(4 * burst, int)])
    o = np.argsort(t, kind="stable")
    ev = Events(x[o].astype(np.uint16), y[o].astype(np.uint16), t[o], p[o].astype(np.int8))
    ev.view_index = np.stack([np.searchsorted(ev.t, exposure[:, 0]), np.searchsorted(ev.t, exposure[:, 1])], 1)
    scene = _scene(blurry, events=ev, exposure=exposure, response=response)
    opts = EdiOptions(threshold=c, mask_top=0.0, per_pixel_threshold=per_pixel, show_progress=False)
    res = compute_edi(scene, opts)
    assert res.mode == "estimated"
    assert np.all(np.isfinite(res.latent)) and res.latent.min() >= 0 and res.latent.max() <= 1
    res.validate("edi.h5")
    # black pixels without events stay black; the blurry frame's black pixels are never brightened by others
    for v in range(2):
        inside = (ev.t >= exposure[v, 0]) & (ev.t < exposure[v, 1])
        quiet = np.ones((h, w), bool)
        quiet[ev.y[inside], ev.x[inside]] = False  # pixels without events inside the exposure
        sel = quiet & (blurry[v, :, :, 0] == pix)
        if sel.any():
            np.testing.assert_allclose(res.latent[v][:, sel], pix / 255.0, atol=2e-6)
