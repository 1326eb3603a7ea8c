"""The davis346 preset and its noise model: the simulated noise rates match the configured ones (Poisson and
binomial intervals computed here from the configuration, independently of the simulator)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom, poisson

from eigs.errors import EigsError
from eigs.synth.generate import generate, intrinsics
from eigs.synth.noise_stats import scene_noise, still_mask
from eigs.synth.scenes import DEFAULTS, PRESET_SOURCES, PRESETS, SCENE_NAMES, resolve_params
from eigs.synth.simulator import LOG_EPS, SensorParams, simulate

LEVEL = 0.999  # two-sided interval used for every rate check
W, H = 32, 24
QUIET = {"threshold_sigma": 0.0, "refractory_us": 0.0, "shot_noise_hz": 0.0, "leak_rate_hz": 0.0}


def v2e_shot_rate(rate_hz: float, factor: float, y_lin: np.ndarray) -> np.ndarray:
    """v2e's intensity-dependent shot-noise rate: rate · ((factor − 1)·inten01 + 1), inten01 = (DN + 20)/275."""
    return rate_hz * ((factor - 1.0) * (255.0 * y_lin + 20.0) / 275.0 + 1.0)


def still_stream(y_lin: np.ndarray, seconds: float, step_us: int = 10_000):
    """Log frames of a still image (H, W) of linear luma ``y_lin`` over ``seconds``."""
    n = int(round(seconds * 1e6 / step_us)) + 1
    logs = np.repeat(np.log(y_lin + LOG_EPS)[None], n, axis=0)
    return logs, np.arange(n, dtype=np.int64) * step_us


def check_poisson(n: int, lam: float) -> None:
    lo, hi = poisson.interval(LEVEL, lam)
    assert lo <= n <= hi, f"{n} events, expected {lam:.1f} (interval [{lo:.0f}, {hi:.0f}])"


def test_shot_noise_rate_on_still_scene_matches_configuration():
    # two intensities: the v2e factor makes the dark half noisier than the bright half
    y = np.full((H, W), 0.02)
    y[:, W // 2 :] = 0.8
    logs, t = still_stream(y, 2.0)
    params = SensorParams(**{**QUIET, "shot_noise_hz": 5.0, "refractory_us": 500.0}, shot_noise_inten_factor=0.25)
    ev, _ = simulate(logs, t, params, np.random.default_rng(3))
    dur = (t[-1] - t[0]) * 1e-6
    dark = ev.x < W // 2
    for sel, yv in ((dark, 0.02), (~dark, 0.8)):
        check_poisson(int(sel.sum()), float(v2e_shot_rate(5.0, 0.25, np.array(yv))) * H * (W // 2) * dur)
    lo, hi = binom.interval(LEVEL, len(ev), 0.5)
    assert lo <= int((ev.p > 0).sum()) <= hi  # random polarity
    assert np.all((ev.t >= t[0]) & (ev.t < t[-1]))


def test_uniform_shot_noise_unchanged_by_default():
    # factor 1 (the default) keeps the intensity-independent model
    logs, t = still_stream(np.full((H, W), 0.3), 1.0)
    ev, _ = simulate(logs, t, SensorParams(**{**QUIET, "shot_noise_hz": 3.0}), np.random.default_rng(0))
    check_poisson(len(ev), 3.0 * H * W * 1.0)


def test_hot_pixels_fire_at_their_rate():
    logs, t = still_stream(np.full((H, W), 0.3), 2.0)
    params = SensorParams(**QUIET, hot_pixel_fraction=0.02, hot_pixel_rate_hz=40.0)
    ev, sim = simulate(logs, t, params, np.random.default_rng(1))
    n_hot = round(0.02 * H * W)
    assert sim.hot_pixels.size == n_hot
    fired = np.unique(ev.y.astype(np.int64) * W + ev.x)
    assert set(fired.tolist()) <= set(sim.hot_pixels.tolist())
    check_poisson(len(ev), n_hot * 40.0 * 2.0)


def test_leak_random_phase_gives_the_rate_from_the_start():
    rate, dur = 0.5, 3.0
    logs, t = still_stream(np.full((H, W), 0.3), dur)
    base = {**QUIET, "leak_rate_hz": rate, "threshold_sigma": 0.03}
    ev, _ = simulate(logs, t, SensorParams(**base, leak_random_phase=True), np.random.default_rng(2))
    counts = np.bincount(ev.y.astype(np.int64) * W + ev.x, minlength=H * W)
    assert np.all(ev.p == 1)  # leak events are ON events
    assert set(np.unique(counts).tolist()) <= {1, 2}  # ⌊u + r·T⌋ with r·T = 1.5
    # mean per pixel r·T; per-pixel count is Bernoulli(0.5) + 1: sd of the mean 0.5/√(HW)
    assert abs(counts.mean() - rate * dur) < 4 * 0.5 / np.sqrt(H * W)
    # without the random phase every pixel's first leak event waits 1/rate = 2 s: one event each
    ev0, _ = simulate(logs, t, SensorParams(**base), np.random.default_rng(2))
    assert np.array_equal(np.bincount(ev0.y.astype(np.int64) * W + ev0.x, minlength=H * W), np.ones(H * W))


def test_leak_rate_spread_is_log_normal():
    logs, t = still_stream(np.full((H, W), 0.3), 1.0)
    params = SensorParams(**{**QUIET, "leak_rate_hz": 0.4}, leak_rate_cov_decades=0.1)
    _, sim = simulate(logs, t, params, np.random.default_rng(4))
    lg = np.log10(sim.leak_rate / 0.4)
    assert abs(lg.mean()) < 4 * 0.1 / np.sqrt(H * W)
    assert abs(lg.std() - 0.1) < 0.01


def test_preset_values_all_cited_and_applied_to_every_scene():
    for name, values in PRESETS.items():
        assert set(values) <= set(DEFAULTS)
        assert set(PRESET_SOURCES[name]) == set(values)
        assert all(PRESET_SOURCES[name][k].strip() for k in values)
    for scene in SCENE_NAMES:
        p = resolve_params(scene, ("cfg", {"preset": "davis346"}))
        assert (p["width"], p["height"], p["n_train"], p["exposure_us"]) == (346, 260, 30, 100_000)
        assert p["light_level"] < 1 and p["shot_noise_hz"] == 5.0
    # user overrides win over the preset; the preset never leaks into scenes without it
    assert resolve_params("toy", ("a", {"preset": "davis346"}), ("b", {"width": 64}))["width"] == 64
    assert resolve_params("toy")["light_level"] == 1.0 and resolve_params("toy")["preset"] is None
    with pytest.raises(EigsError, match="preset"):
        resolve_params("toy", ("x", {"preset": "davis999"}))


def test_preset_still_scene_rate_within_interval(tmp_path):
    """The generator with the preset, camera held still in every exposure (shake 0): the events inside the
    exposures are noise only; their count matches Σ shot-noise rate(pixel) + hot pixels + leak."""
    from eigs.scene import write_scene

    ov = {"preset": "davis346", "width": W, "height": H, "n_train": 6, "n_novel": 0, "subframes": 8,
          "gap_subframes": 4, "lead_subframes": 1, "supersample": 1, "texture_size": 32, "shake": 0.0}
    g = generate("toy", ov, show_progress=False)
    p, s = g.params, g.scene
    lam = 0.0
    for v in range(s.n_views):
        y = (s.frames.blurry[v].astype(np.float64) / 255.0) @ np.array([0.299, 0.587, 0.114])
        lam += v2e_shot_rate(p["shot_noise_hz"], p["shot_noise_inten_factor"], y).sum() * 0.1
    n_hot = round(p["hot_pixel_fraction"] * W * H)
    lam += s.n_views * 0.1 * (n_hot * p["hot_pixel_rate_hz"])
    leak = s.n_views * 0.1 * p["leak_rate_hz"] * W * H * 1.03  # steady-state leak (log-normal mean factor)
    n = int((s.events.view_index[:, 1] - s.events.view_index[:, 0]).sum())
    lo, hi = poisson.interval(LEVEL, lam)
    assert lo <= n <= hi + leak + 4 * np.sqrt(leak), (n, lam, leak)
    # the measurement tool sees the same: every pixel of these flat still frames may count as still
    path = tmp_path / "s.h5"
    write_scene(s, path)
    st = scene_noise(path)
    assert st["still_events"] <= n and st["still_on_fraction_ci95"][0] < 0.6


def test_full_size_single_frame():
    """346×260 once: one view, a few sub-frames; frames at the preset's light level."""
    ov = {"preset": "davis346", "n_train": 1, "n_novel": 0, "subframes": 4, "gap_subframes": 1,
          "lead_subframes": 1, "supersample": 1}
    dim = generate("blocks", ov, show_progress=False)
    bright = generate("blocks", {**ov, "light_level": 1.0}, show_progress=False)
    assert dim.scene.frames.blurry.shape == (1, 260, 346, 3)
    np.testing.assert_allclose(dim.scene.camera.K, intrinsics(346, 260, 60.0))
    ratio = dim.scene.frames.blurry.astype(float).mean() / bright.scene.frames.blurry.astype(float).mean()
    assert abs(ratio - 0.4) < 0.01
    assert still_mask(dim.scene.frames.blurry[0]).shape == (260, 346)
