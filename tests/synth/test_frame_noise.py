"""The DAVIS346 APS frame noise: on a still, flat scene the frames show the configured temporal noise (variance over
frames per pixel), pixel fixed-pattern noise (variance over pixels of the temporal mean, column means removed) and
column FPN (variance over columns), each inside its 99.9 % chi-square interval computed here from the configuration
and the sample sizes; the fixed pattern is one per scene; noise-free frames are the default and unchanged."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from eigs.synth.frame_noise import MODELS, draw_fixed_pattern, expose
from eigs.synth.generate import _frame_noise, generate
from eigs.synth.scenes import PRESETS, resolve_params

LEVEL = 0.999
MODEL = MODELS["davis346"]
H, W, FRAMES = 260, 346, 40  # the sensor's array


def check_chi2(sum_of_squares: float, variance: float, dof: int, what: str) -> None:
    """``sum_of_squares / variance`` must lie in the two-sided ``LEVEL`` interval of chi-square with ``dof``."""
    lo, hi = chi2.interval(LEVEL, dof)
    stat = sum_of_squares / variance
    ratio = (stat / dof) ** 0.5
    assert lo <= stat <= hi, (f"{what}: measured std / configured std = {ratio:.4f}, outside "
                              f"[{(lo / dof) ** 0.5:.4f}, {(hi / dof) ** 0.5:.4f}]")  # fmt: skip


@pytest.fixture(scope="module", params=[0.06, 0.5])  # the preset's dark frames (≈ 15 DN) and mid-scale
def still(request):
    x = request.param
    rng = np.random.default_rng(11)
    pattern = draw_fixed_pattern(MODEL, H, W, 1, rng)
    clean = np.full((H, W, 1), x)
    frames = np.stack([expose(clean, MODEL, pattern, rng) for _ in range(FRAMES)])  # (N, H, W, 1)
    return x, pattern, frames


def test_temporal_noise_matches_read_and_shot_noise(still):
    x, pattern, frames = still
    var = MODEL.temporal_variance(x, pattern.gain)  # per pixel: the gain error scales its shot noise
    ss = ((frames - frames.mean(axis=0)) ** 2).sum(axis=0)  # (n − 1) s² per pixel
    check_chi2(float((ss / var).sum()), 1.0, H * W * (FRAMES - 1), "temporal")
    # the figure docs/synthetic.md reports: the rms over pixels of the per-pixel std, in DN
    std_dn = float(np.sqrt((ss / (FRAMES - 1)).mean())) * 255
    assert std_dn == pytest.approx(float(np.sqrt(var.mean())) * 255, rel=0.01)


def test_pixel_and_column_fixed_pattern_noise(still):
    x, _, frames = still
    mean = frames.mean(axis=0)[:, :, 0]  # (H, W): the temporal mean of each pixel
    t_var = float(MODEL.temporal_variance(x)) / FRAMES  # what the temporal noise leaves in the mean
    per_pixel = MODEL.pixel_fpn_fs**2 + (x * MODEL.prnu) ** 2 + t_var  # offset, gain × signal, residual noise
    # pixel FPN: the spread within each column (its column offset removed); (H − 1) dof per column
    resid = mean - mean.mean(axis=0, keepdims=True)
    check_chi2(float((resid**2).sum()), per_pixel, W * (H - 1), "pixel FPN")
    # column FPN: the spread of the column means, which also carry the pixel terms averaged over H rows
    col = mean.mean(axis=0)
    check_chi2(float(((col - col.mean()) ** 2).sum()), MODEL.column_fpn_fs**2 + per_pixel / H, W - 1, "column FPN")
    # the intervals can fail: half or twice the configured column FPN lies far outside
    lo, hi = chi2.interval(LEVEL, W - 1)
    for wrong in (0.5, 2.0):
        stat = float(((col - col.mean()) ** 2).sum()) / ((wrong * MODEL.column_fpn_fs) ** 2 + per_pixel / H)
        assert not lo <= stat <= hi


def test_the_configured_values_and_their_sources():
    from eigs.synth.frame_noise import SOURCES

    assert MODEL.read_noise_fs * 255 == pytest.approx(0.7187, abs=1e-4)  # 51 dB below full scale, in DN
    assert np.hypot(MODEL.column_fpn_fs, MODEL.pixel_fpn_fs) == pytest.approx(0.005)  # Brandli et al.'s 0.5 %
    assert MODEL.full_well_e / 255 == pytest.approx(160.8, abs=0.1)  # e⁻ per 8-bit DN
    assert set(SOURCES["davis346"]) == {"full_well_e", "read_noise_fs", "column_fpn_fs", "pixel_fpn_fs", "prnu"}


def test_one_fixed_pattern_per_scene_and_the_default_is_noise_free():
    p = resolve_params("toy", ("test", {"frame_noise": "davis346", "seed": 4}))
    flat = np.full((6, 8, 3), 0.3)

    def sensor():
        return _frame_noise(p, np.random.default_rng(p["seed"]), 6, 8, 3)

    aps = sensor()
    a = np.stack([aps(flat) for _ in range(400)])
    # the same sensor: the mean over frames converges to one pattern; frame to frame only temporal noise
    d = a[1:] - a[:-1]
    assert d.std() == pytest.approx(np.sqrt(2 * MODEL.temporal_variance(0.3)), rel=0.05)
    np.testing.assert_array_equal(sensor()(flat), a[0])  # seeded by the scene: the same sensor again
    # one column offset for all channels: the channels' column means differ only by pixel FPN over 6 rows
    cols = (a.mean(axis=0) - 0.3).mean(axis=0)  # (W, C)
    assert np.abs(cols[:, 0] - cols[:, 1]).max() < 4 * MODEL.pixel_fpn_fs * np.sqrt(2 / 6)
    assert np.abs(cols).max() > 0.5 * MODEL.column_fpn_fs  # and there is a column pattern
    # noise off: no function, and the preset leaves it off
    assert _frame_noise(resolve_params("toy"), np.random.default_rng(0), 6, 8, 3) is None
    assert resolve_params("toy", ("t", {"preset": "davis346"}))["frame_noise"] == "none"
    assert "frame_noise" not in PRESETS["davis346"]


def test_generator_adds_noise_to_the_blurry_frames_only():
    small = {"width": 32, "height": 24, "n_train": 2, "n_novel": 1, "subframes": 4, "gap_subframes": 4,
             "lead_subframes": 1, "supersample": 1, "texture_size": 32, "seed": 2}  # fmt: skip
    clean = generate("toy", small, show_progress=False).scene
    again = generate("toy", {**small, "frame_noise": "none"}, show_progress=False).scene
    noisy = generate("toy", {**small, "frame_noise": "davis346"}, show_progress=False).scene
    np.testing.assert_array_equal(clean.frames.blurry, again.frames.blurry)
    assert clean.source == again.source == "eigs synth --scene toy (seed 2)"
    assert noisy.source == "eigs synth --scene toy (seed 2, frame noise davis346)"
    # the events, the ground truth and the poses do not move; the frames differ by about the noise
    np.testing.assert_array_equal(clean.events.t, noisy.events.t)
    np.testing.assert_array_equal(clean.events.x, noisy.events.x)
    np.testing.assert_array_equal(clean.sharp.images, noisy.sharp.images)
    diff = noisy.frames.blurry.astype(float) - clean.frames.blurry
    assert 0.5 < diff.std() < 4.0 and abs(diff.mean()) < 0.5
