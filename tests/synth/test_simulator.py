"""Event simulator against closed forms: linear ramps, static scenes, net counts over an exposure, threshold
mismatch, refractory period, noise. Unless a test says otherwise: σ = 0, equal thresholds, no refractory
period, no noise, reference reset at the exposure start (the first frame)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from eigs.synth.simulator import EventSimulator, SensorParams, log_luma, simulate

IDEAL = dict(threshold_sigma=0.0, refractory_us=0.0, shot_noise_hz=0.0, leak_rate_hz=0.0)


def ramp_frames(l0: np.ndarray, l1: np.ndarray, t_end_us: int, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Frames of per-pixel linear log ramps from ``l0`` to ``l1`` (H, W) over [0, t_end_us] (integer µs)."""
    t = np.linspace(0, t_end_us, n_frames).round().astype(np.int64)
    u = (t / t_end_us)[:, None, None]
    return l0[None] + u * (l1 - l0)[None], t


@pytest.mark.parametrize("n_frames", [2, 7, 101])
@pytest.mark.parametrize("c", [0.2, 0.15])
def test_linear_ramp_counts_and_times(n_frames, c):
    rng = np.random.default_rng(1)
    h, w = 3, 5
    l0 = rng.uniform(-4, -1, (h, w))
    dl = rng.uniform(-2.3, 2.3, (h, w))
    dl[0, 0], dl[0, 1] = 1.07, -0.93  # at least one clear ramp each way
    T = 100_000
    frames, t = ramp_frames(l0, l0 + dl, T, n_frames)
    ev, _ = simulate(frames, t, SensorParams(contrast_threshold=c, **IDEAL))
    for i in range(h):
        for j in range(w):
            m = (ev.y == i) & (ev.x == j)
            n_expected = int(np.floor(abs(dl[i, j]) / c))
            assert m.sum() == n_expected, (i, j, dl[i, j])
            if n_expected == 0:
                continue
            assert np.all(ev.p[m] == np.sign(dl[i, j]))
            k = np.arange(1, n_expected + 1)
            t_exact = k * c / abs(dl[i, j]) * T  # L(t) = l0 + dl·t/T crosses l0 ± k·c
            assert np.all(np.abs(ev.t[m] - t_exact) <= 1.0), (ev.t[m], t_exact)


def test_static_scene_emits_nothing():
    rng = np.random.default_rng(2)
    frame = rng.uniform(-6, 0, (8, 9))
    frames = np.repeat(frame[None], 20, axis=0)
    t = np.arange(20, dtype=np.int64) * 1000
    ev, _ = simulate(frames, t, SensorParams(**IDEAL))
    assert len(ev) == 0
    # with mismatch and a refractory period too
    ev, _ = simulate(frames, t, SensorParams(threshold_sigma=0.03, refractory_us=100.0))
    assert len(ev) == 0


def random_stream(rng: np.random.Generator, n: int, h: int, w: int) -> np.ndarray:
    """Smooth-ish random log-intensity videos with large excursions (several thresholds per step)."""
    steps = rng.normal(0, 0.25, (n, h, w)).cumsum(axis=0)
    return np.log(0.3 + 0.2 * np.sin(np.arange(n)[:, None, None] / 3.0)) + steps


def net_counts(ev, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    on = np.zeros(h * w)
    off = np.zeros(h * w)
    idx = ev.y.astype(np.int64) * w + ev.x
    np.add.at(on, idx[ev.p > 0], 1)
    np.add.at(off, idx[ev.p < 0], 1)
    return on.reshape(h, w), off.reshape(h, w)


def test_net_count_over_exposure_matches_log_change():
    rng = np.random.default_rng(3)
    h, w, n = 16, 12, 60
    frames = random_stream(rng, n, h, w)
    t = np.arange(n, dtype=np.int64) * 1250
    c = 0.2
    ev, _ = simulate(frames, t, SensorParams(contrast_threshold=c, **IDEAL))
    on, off = net_counts(ev, h, w)
    dl = frames[-1] - frames[0]
    assert np.all(np.abs((on - off) - dl / c) < 1.0)


def test_net_count_with_mismatch_uses_each_pixels_thresholds():
    rng = np.random.default_rng(4)
    h, w, n = 16, 12, 60
    frames = random_stream(rng, n, h, w)
    t = np.arange(n, dtype=np.int64) * 1250
    params = SensorParams(contrast_threshold=0.2, threshold_sigma=0.03, refractory_us=0.0)
    ev, sim = simulate(frames, t, params, np.random.default_rng(9))
    assert sim.c_on.std() > 0.01 and not np.allclose(sim.c_on, sim.c_off)  # mismatch is on
    on, off = net_counts(ev, h, w)
    dl = frames[-1] - frames[0]
    # the reference moved by on·C_on − off·C_off and ends within (−C_off, C_on) of L
    resid = dl - (on * sim.c_on - off * sim.c_off)
    assert np.all(resid < sim.c_on) and np.all(resid > -sim.c_off)
    # a monotone ramp crosses only one polarity: |n − ΔL/C_pixel| < 1 with the pixel's own threshold
    l0 = np.full((h, w), -3.0)
    dlr = rng.uniform(-2, 2, (h, w))
    frames_r, tr = ramp_frames(l0, l0 + dlr, 50_000, 41)
    ev, sim = simulate(frames_r, tr, params, np.random.default_rng(9))
    on, off = net_counts(ev, h, w)
    c_pix = np.where(dlr > 0, sim.c_on, sim.c_off)
    assert np.all(np.abs((on - off) - dlr / c_pix) < 1.0)
    assert np.all(on - off == np.sign(dlr) * np.floor(np.abs(dlr) / c_pix))


def test_reset_at_exposure_start():
    rng = np.random.default_rng(5)
    h, w = 6, 7
    frames = random_stream(rng, 40, h, w)
    t = np.arange(40, dtype=np.int64) * 1000
    start = 10
    ev, _ = simulate(frames, t, SensorParams(contrast_threshold=0.2, **IDEAL), reset_times_us=[t[start]])
    sel = ev.t >= t[start]
    on = np.zeros((h, w))
    np.add.at(on, (ev.y[sel], ev.x[sel]), ev.p[sel].astype(float))
    assert np.all(np.abs(on - (frames[-1] - frames[start]) / 0.2) < 1.0)


def expected_refractory(times: np.ndarray, refractory: float) -> np.ndarray:
    """Independent sequential reference: keep an event if it is ≥ refractory after the last kept one."""
    kept, last = [], -np.inf
    for t in times:
        if t - last >= refractory:
            kept.append(t)
            last = t
    return np.asarray(kept)


@pytest.mark.parametrize("frame_step_us", [50, 1000, 1500])
def test_refractory_drops_exactly_the_right_events(frame_step_us):
    # L rises by C every 100 µs: crossings at 100, 200, ..., 3000 µs (30 of them)
    c, T = 0.2, 3000
    l0 = np.array([[-3.0]])
    frames, t = ramp_frames(l0, l0 + 30.05 * c, T, T // frame_step_us + 1)
    crossings = np.arange(1, 31) * 100.0 * (30.0 / 30.05)
    for refr in (0.0, 150.0, 250.0, 1000.0):
        ev, sim = simulate(frames, t, SensorParams(contrast_threshold=c, **{**IDEAL, "refractory_us": refr}))
        want = expected_refractory(crossings, refr)
        assert len(ev) == len(want), refr
        assert np.all(np.abs(ev.t - want) <= 1.0)
        assert sim.crossings == 30  # the reference moved through every crossing, emitted or not


def test_refractory_closed_form():
    """Crossings every 100 µs, refractory 250 µs: exactly every third crossing is emitted (100, 400, 700...)."""
    c = 0.2
    l0 = np.array([[-3.0]])
    frames, t = ramp_frames(l0, l0 + 30.5 * c, 3050, 62)
    ev, _ = simulate(frames, t, SensorParams(contrast_threshold=c, **{**IDEAL, "refractory_us": 250.0}))
    assert len(ev) == 10 and np.all(np.abs(ev.t - np.arange(100, 3001, 300)) <= 1)


def test_asymmetric_thresholds():
    l0 = np.array([[-3.0, -1.0]])
    l1 = np.array([[-1.0, -3.0]])
    frames, t = ramp_frames(l0, l1, 10_000, 21)
    p = SensorParams(threshold_pos=0.3, threshold_neg=0.15, **IDEAL)
    ev, _ = simulate(frames, t, p)
    assert np.sum((ev.x == 0) & (ev.p == 1)) == 6  # ⌊2/0.3⌋
    assert np.sum((ev.x == 1) & (ev.p == -1)) == 13  # ⌊2/0.15⌋
    assert len(ev) == 19


def test_event_times_stay_inside_their_step_and_are_sorted():
    rng = np.random.default_rng(6)
    frames = random_stream(rng, 30, 10, 10)
    t = np.arange(30, dtype=np.int64) * 1000
    ev, _ = simulate(frames, t, SensorParams(shot_noise_hz=500.0, leak_rate_hz=5.0))
    assert np.all(np.diff(ev.t) >= 0)
    assert ev.t.min() >= 0 and ev.t.max() < t[-1]
    assert ev.t.dtype == np.int64 and ev.p.dtype == np.int8 and ev.x.dtype == np.uint16


def test_shot_noise_rate_and_leak_rate():
    frames = np.full((101, 20, 20), -2.0)
    t = np.arange(101, dtype=np.int64) * 10_000  # 1 s
    ev, _ = simulate(frames, t, SensorParams(shot_noise_hz=2.0, threshold_sigma=0.0, refractory_us=0.0),
                     np.random.default_rng(0))
    assert abs(len(ev) - 800) < 5 * np.sqrt(800)  # Poisson(2 Hz × 400 px × 1 s)
    assert abs(np.mean(ev.p == 1) - 0.5) < 0.1
    ev, _ = simulate(frames, t, SensorParams(leak_rate_hz=3.0, threshold_sigma=0.0, refractory_us=0.0))
    assert np.all(ev.p == 1)
    counts = np.bincount(ev.y.astype(int) * 20 + ev.x, minlength=400)
    assert np.all(counts == 3)  # drift of 3·C over 1 s → exactly 3 ON events per pixel


def test_log_luma_definition():
    rgb = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.2, 0.5, 0.9]])
    y = 0.299 * rgb[:, 0] + 0.587 * rgb[:, 1] + 0.114 * rgb[:, 2]
    assert np.allclose(log_luma(rgb), np.log(y + 1e-3))
    assert np.isfinite(log_luma(np.zeros((2, 2, 3)))).all()


def test_step_requires_increasing_time():
    sim = EventSimulator(2, 2, SensorParams(**IDEAL), np.random.default_rng(0))
    sim.reset(np.zeros((2, 2)), 0)
    with pytest.raises(ValueError):
        sim.step(np.zeros((2, 2)), 0)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    c_pos=st.floats(0.05, 0.6),
    c_neg=st.floats(0.05, 0.6),
    n=st.integers(2, 30),
    step_us=st.integers(1, 5000),
)
def test_reference_invariant_property(seed, c_pos, c_neg, n, step_us):
    """For any stream and thresholds: the reference ends within (−C_off, C_on) of L, events = crossings, and
    ON·C_on − OFF·C_off equals the reference's total move."""
    rng = np.random.default_rng(seed)
    frames = rng.normal(0, 1.0, (n, 3, 4)).cumsum(axis=0)
    t = np.arange(n, dtype=np.int64) * step_us
    params = SensorParams(threshold_pos=c_pos, threshold_neg=c_neg, **IDEAL)
    ev, sim = simulate(frames, t, params)
    on, off = net_counts(ev, 3, 4)
    resid = frames[-1] - sim.ref
    assert np.all(resid < c_pos + 1e-9) and np.all(resid > -c_neg - 1e-9)
    assert np.allclose(sim.ref - frames[0], on * c_pos - off * c_neg)
    assert len(ev) == sim.crossings
    assert np.all(np.diff(ev.t) >= 0) and (len(ev) == 0 or ev.t.max() < t[-1])
