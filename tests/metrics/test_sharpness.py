"""The high-frequency power ratio against closed forms: an image blurred by a known Gaussian kernel keeps the mean of
the kernel's squared transfer function over the band (computed here in float64 from the Gaussian's analytic Fourier
transform, not from an FFT), identity gives 1, contrast scales it quadratically, a flat ground truth is refused. The
high-frequency coherence likewise: the band mean of the transfer function itself, linear in contrast, blind to
independent noise that the power ratio counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eigs.errors import EigsError
from eigs.metrics.sharpness import CUTOFF, UndefinedSharpness, hf_coherence, hf_ratio


def sampled_gaussian(sigma: float, radius: int) -> np.ndarray:
    """The 1-D Gaussian sampled at integers -radius..radius, normalised to sum 1."""
    n = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-(n**2) / (2 * sigma**2))
    return g / g.sum()


def transfer(f: np.ndarray, sigma: float, radius: int) -> np.ndarray:
    """DTFT of :func:`sampled_gaussian` at ``f`` cycles/pixel, by Poisson summation of the continuous Gaussian's
    Fourier transform exp(-2π²σ²f²): (σ√(2π)/Z) Σ_k exp(-2π²σ²(f + k)²), Z the sampled kernel's sum."""
    z = np.exp(-(np.arange(-radius, radius + 1) ** 2) / (2 * sigma**2)).sum()
    k = np.arange(-6, 7)[:, None]
    return sigma * math.sqrt(2 * math.pi) / z * np.exp(-2 * math.pi**2 * sigma**2 * (f[None, :] + k) ** 2).sum(0)


def expected_ratio(n: int, sigma: float, radius: int, power: int = 2) -> float:
    """Mean of |G(fx) G(fy)|² over the DFT bins of an n × n image with radial frequency >= CUTOFF: the power a
    flat-spectrum image keeps after the blur, relative to before (``power`` 1: the mean of G(fx) G(fy), the
    coherence of the blurred image with the sharp one; the sampled Gaussian is real and even, so G is real)."""
    f = np.arange(n, dtype=np.float64)
    f = np.where(f < (n + 1) // 2, f, f - n) / n  # the DFT grid in cycles/pixel, written out
    g2 = transfer(f, sigma, radius) ** power
    band = np.hypot(f[:, None], f[None, :]) >= CUTOFF
    return float((g2[:, None] * g2[None, :])[band].mean())


def circular_blur(img: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Separable circular convolution of ``img`` (H, W) with a centred odd-length 1-D ``kernel``, by shifted sums."""
    r = len(kernel) // 2
    rows = sum(kernel[i] * np.roll(img, i - r, axis=1) for i in range(len(kernel)))
    return sum(kernel[i] * np.roll(rows, i - r, axis=0) for i in range(len(kernel)))


@pytest.mark.parametrize("sigma", [0.4, 0.6, 0.8])
def test_blurred_impulse_keeps_the_kernels_band_power(sigma):
    # an impulse at the centre of an odd-sized image has a flat spectrum and sits where the Hann window is 1, so the
    # blurred impulse (the kernel itself) keeps the band mean of |G|² up to the window's curvature over the
    # kernel's support (measured: < 2e-4 relative at these widths)
    n, radius = 257, int(math.ceil(8 * sigma))
    gt = np.full((n, n), 0.25)
    gt[n // 2, n // 2] += 0.5
    k = sampled_gaussian(sigma, radius)
    render = np.full((n, n), 0.25)
    c = n // 2
    render[c - radius : c + radius + 1, c - radius : c + radius + 1] += 0.5 * np.outer(k, k)
    want = expected_ratio(n, sigma, radius)
    assert 0.02 < want < 0.7
    assert hf_ratio(render, gt) == pytest.approx(want, rel=1e-3)


@pytest.mark.parametrize("sigma", [0.5, 0.7])
def test_blurred_white_noise_keeps_the_kernels_band_power(sigma):
    # textured ground truths (white noise: an expected flat spectrum) blurred circularly: each ratio is a weighted
    # mean of |G|² over the band with random weights, so the mean over 16 images must lie within 5 standard errors
    # (from the sample) of the closed form, plus 1e-3 for the window's smoothing of |G|²; a kernel 3 % wider moves
    # the closed form by more than that
    n, radius, count = 256, int(math.ceil(8 * sigma)), 16
    kernel = sampled_gaussian(sigma, radius)
    ratios = []
    for seed in range(count):
        gt = np.random.default_rng(seed).random((n, n))
        ratios.append(hf_ratio(circular_blur(gt, kernel), gt))
    want = expected_ratio(n, sigma, radius)
    rel = np.asarray(ratios) / want - 1
    se = float(rel.std(ddof=1)) / math.sqrt(count)
    assert se < 0.005
    assert abs(float(rel.mean())) < 5 * se + 1e-3
    assert abs(expected_ratio(n, 1.03 * sigma, radius) / want - 1) > 5 * se + 1e-3


def test_identity_gives_one_and_contrast_scales_quadratically():
    rng = np.random.default_rng(1)
    gt = rng.random((40, 60, 3))
    assert hf_ratio(gt, gt) == 1.0
    u8 = (gt * 255).astype(np.uint8)
    assert hf_ratio(u8, u8) == 1.0
    gray = rng.random((48, 64))
    half = 0.5 + 0.5 * (gray - 0.5)  # half the contrast: a quarter of the power
    assert hf_ratio(half, gray) == pytest.approx(0.25, rel=1e-12)
    # grey RGB is its own luminance: the same ratio as the 1-channel image
    assert hf_ratio(np.repeat(half[:, :, None], 3, 2), gray) == pytest.approx(0.25, rel=1e-12)


def test_flat_ground_truth_is_undefined_and_a_flat_render_keeps_nothing():
    rng = np.random.default_rng(2)
    textured = rng.random((32, 32))
    for flat in (np.full((32, 32), 0.3), np.full((32, 32), 77, dtype=np.uint8)):
        with pytest.raises(UndefinedSharpness, match="undefined"):
            hf_ratio(textured, flat)
    assert issubclass(UndefinedSharpness, EigsError)
    assert hf_ratio(np.full((32, 32), 0.3), textured) < 1e-20
    # a ramp is smooth: (almost) no power above 0.25 cycles/pixel, far below a textured render's
    ramp = np.tile(np.linspace(0.2, 0.8, 32), (32, 1))
    assert hf_ratio(ramp, textured) < 1e-3


def test_size_and_shape_checks():
    with pytest.raises(EigsError, match="at least 8"):
        hf_ratio(np.zeros((4, 32)), np.zeros((4, 32)))
    with pytest.raises(EigsError, match="sizes must match"):
        hf_ratio(np.zeros((16, 16)), np.zeros((16, 20)))


@pytest.mark.parametrize("sigma", [0.4, 0.8])
def test_coherence_of_a_blurred_impulse_is_the_band_mean_of_the_transfer_function(sigma):
    n, radius = 257, int(math.ceil(8 * sigma))
    gt = np.full((n, n), 0.25)
    gt[n // 2, n // 2] += 0.5
    render = np.full((n, n), 0.25)
    c = n // 2
    k = sampled_gaussian(sigma, radius)
    render[c - radius : c + radius + 1, c - radius : c + radius + 1] += 0.5 * np.outer(k, k)
    want = expected_ratio(n, sigma, radius, power=1)
    assert want > expected_ratio(n, sigma, radius) + 0.01  # the mean of G, not of G²
    assert hf_coherence(render, gt) == pytest.approx(want, rel=1e-3)


def test_coherence_is_linear_in_contrast_and_zero_for_flat_or_counter_phase_detail():
    rng = np.random.default_rng(3)
    gt = rng.random((48, 64))
    assert hf_coherence(gt, gt) == pytest.approx(1.0, rel=1e-12)
    assert hf_coherence(0.5 + 0.3 * (gt - 0.5), gt) == pytest.approx(0.3, rel=1e-12)
    assert hf_coherence(1.0 - gt, gt) == pytest.approx(-1.0, rel=1e-12)
    assert abs(hf_coherence(np.full((48, 64), 0.4), gt)) < 1e-12
    with pytest.raises(UndefinedSharpness, match="coherence is undefined"):
        hf_coherence(gt, np.full((48, 64), 0.4))


def test_independent_noise_raises_the_power_ratio_but_not_the_coherence():
    # render = ground truth + white noise of the same variance: the power ratio doubles (about 2), the coherence
    # stays 1 up to the noise's chance correlation with the ground truth (mean of 8 images within 5 standard errors)
    n, count = 128, 8
    ratios, coherences = [], []
    for seed in range(count):
        rng = np.random.default_rng(100 + seed)
        gt = 0.25 + 0.5 * rng.random((n, n))
        render = gt + 0.5 * (rng.random((n, n)) - 0.5)  # in [0, 1]
        ratios.append(hf_ratio(render, gt))
        coherences.append(hf_coherence(render, gt))
    assert 1.8 < float(np.mean(ratios)) < 2.2
    se = float(np.std(coherences, ddof=1)) / math.sqrt(count)
    assert 0 < se < 0.01 and abs(float(np.mean(coherences)) - 1.0) < 5 * se


def test_coherence_of_a_shifted_impulse_is_the_band_mean_of_the_phase_cosine():
    # the impulse moved by d pixels along x: its spectrum turns by 2π fx d, so the coherence is the band mean of
    # cos(2π fx d) (the window is flat to second order near the centre: within 2e-3 for shifts of a few pixels)
    n = 257
    gt = np.full((n, n), 0.25)
    gt[n // 2, n // 2] += 0.5
    f = np.fft.fftfreq(n)
    band = np.hypot(f[:, None], f[None, :]) >= CUTOFF
    for d in (1, 2):
        shifted = np.roll(gt, d, axis=1)
        want = float(np.broadcast_to(np.cos(2 * np.pi * f[None, :] * d), (n, n))[band].mean())
        assert hf_coherence(shifted, gt) == pytest.approx(want, abs=2e-3)
        assert hf_ratio(shifted, gt) == pytest.approx(1.0, abs=2e-3)  # the power ratio does not see the shift
