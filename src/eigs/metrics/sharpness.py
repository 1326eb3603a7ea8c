"""Sharpness of a render against its ground truth: the high-frequency power ratio.

Definition (one image pair, ``docs/metrics.md``, "Sharpness"):

1. Luminance ``Y`` ``(H, W)`` float64 of each image on the [0, 1] scale, values as stored (8-bit renders are
   divided by 255, no linearisation): a 1-channel image as is, RGB as ``0.2126 R + 0.7152 G + 0.0722 B``
   (ITU-R BT.709 weights).
2. ``Y`` minus its mean, times a separable 2-D Hann window ``w[i, j] = h_H[i] h_W[j]``,
   ``h_N[n] = 0.5 − 0.5 cos(2π n / (N − 1))`` (``numpy.hanning``), so the image's borders do not add the
   spectral leakage of a periodic discontinuity.
3. Its 2-D DFT ``F`` on the grid ``fx = numpy.fft.fftfreq(W)``, ``fy = numpy.fft.fftfreq(H)`` (cycles/pixel) and
   the band power ``P = Σ_{|f| ≥ 0.25} |F(f)|² / (H W Σ w²)``, ``|f| = sqrt(fx² + fy²)``: the band-passed
   variance per pixel (units: [0, 1]² of the image scale; the normalisation cancels in the ratio).
4. ``hf_ratio(render, gt) = P(render) / P(gt)``: a dimensionless float64, the fraction of the ground truth's
   power above 0.25 cycles/pixel (half the Nyquist frequency) that the render keeps. 1: as much as the ground
   truth; below 1: smoother; above 1: more than the ground truth has (noise, ringing, aliasing), so the ratio
   measures sharpness, not fidelity, and reads beside PSNR / SSIM / LPIPS. The tables print 3 decimals.

The ratio is undefined where the ground truth has (almost) no power in the band: ``P(gt) < MIN_BAND_POWER``
(an rms of 1e-6 on the [0, 1] scale, far below one 8-bit step of 1/255). :func:`hf_ratio` then raises
:class:`EigsError` (:class:`UndefinedSharpness`) rather than return NaN or infinity; ``eigs evaluate`` counts such
views in ``sharpness_undefined`` and leaves them out of the mean, as it does for BRISQUE.
"""

from __future__ import annotations

import numpy as np

from eigs.errors import EigsError
from eigs.metrics.image import float_pair

CUTOFF = 0.25  # cycles/pixel: the band is |f| >= CUTOFF
MIN_BAND_POWER = 1e-12  # [0, 1]² per pixel: below it the ground truth is flat in the band
MIN_SIZE = 8  # pixels along each axis
LUMA = np.array([0.2126, 0.7152, 0.0722])  # ITU-R BT.709


class UndefinedSharpness(EigsError):
    """The ground truth has no power above :data:`CUTOFF`: the ratio is undefined for this pair."""


def luminance(img: np.ndarray) -> np.ndarray:
    """``(H, W)`` float64 luminance of an ``(H, W, C)`` float image, C in {1, 3} (BT.709 weights for RGB)."""
    return img[:, :, 0] if img.shape[2] == 1 else img @ LUMA


def band_mask(height: int, width: int, cutoff: float = CUTOFF) -> np.ndarray:
    """``(H, W)`` bool: the DFT bins (``numpy.fft.fft2`` order) whose radial frequency is at least ``cutoff``."""
    fy = np.fft.fftfreq(height)[:, None]
    fx = np.fft.fftfreq(width)[None, :]
    return np.hypot(fx, fy) >= cutoff


def _band_spectrum(y: np.ndarray, cutoff: float) -> tuple[np.ndarray, float]:
    """The DFT bins of ``y`` ``(H, W)`` in the band (mean removed, Hann window) and the normalisation ``H W Σ w²``."""
    h, w = y.shape
    if min(h, w) < MIN_SIZE:
        raise EigsError(None, f"image is {w}x{h}; the sharpness ratio needs at least {MIN_SIZE} pixels per side")
    window = np.outer(np.hanning(h), np.hanning(w))
    spectrum = np.fft.fft2((y - y.mean()) * window)
    return spectrum[band_mask(h, w, cutoff)], h * w * float(np.sum(window**2))


def _band_power(band: np.ndarray, norm: float) -> float:
    """Band power ``P`` (module docstring) from :func:`_band_spectrum`'s bins and normalisation: variance per pixel
    above the cutoff after mean removal and the Hann window, in [0, 1]² units."""
    return float(np.sum(band.real**2 + band.imag**2) / norm)


def _reference_band(ref: np.ndarray, cutoff: float, figure: str) -> tuple[np.ndarray, float, float]:
    """The band bins, normalisation and band power of a ground truth's luminance ``ref``; raises
    :class:`UndefinedSharpness` (naming ``figure``) when the power is below :data:`MIN_BAND_POWER`."""
    band, norm = _band_spectrum(ref, cutoff)
    power = _band_power(band, norm)
    if power < MIN_BAND_POWER:
        raise UndefinedSharpness(
            None,
            f"the reference has no power above {cutoff} cycles/pixel (band variance {power:.3g} < "
            f"{MIN_BAND_POWER:g}): the {figure} is undefined",
        )
    return band, norm, power


def _scores(img: np.ndarray, ref: np.ndarray, cutoff: float, figure: str) -> tuple[float, float]:
    """The power ratio and the coherence of ``img`` against ``ref`` (their band bins computed once); an undefined
    reference raises :class:`UndefinedSharpness` naming ``figure``."""
    a, b = float_pair(img, ref)
    band_ref, norm, p_ref = _reference_band(luminance(b), cutoff, figure)
    band_img, _ = _band_spectrum(luminance(a), cutoff)
    cross = float(np.sum(band_img.real * band_ref.real + band_img.imag * band_ref.imag) / norm)
    return _band_power(band_img, norm) / p_ref, cross / p_ref


def hf_ratio(img: np.ndarray, ref: np.ndarray, cutoff: float = CUTOFF) -> float:
    """High-frequency power ratio of ``img`` (a render) against ``ref`` (its ground truth): ``P(img) / P(ref)``.

    Inputs as in :mod:`eigs.metrics.image`: ``(H, W[, C])`` uint8 or float in [0, 1], same H and W (at least
    :data:`MIN_SIZE`). Returns a finite float >= 0. Raises :class:`UndefinedSharpness` when the reference's band
    power is below :data:`MIN_BAND_POWER` (a flat ground truth).
    """
    return _scores(img, ref, cutoff, "sharpness ratio")[0]


def hf_coherence(img: np.ndarray, ref: np.ndarray, cutoff: float = CUTOFF) -> float:
    """The part of ``ref``'s high-frequency content that ``img`` reproduces: ``Re Σ F_img conj(F_ref) / Σ |F_ref|²``
    over the band of :func:`hf_ratio` (same luminance, mean removal and window). 1: the ground truth's detail, in
    phase and at full amplitude; ``a`` for a render whose detail is the ground truth's times ``a``; about 0 for a
    flat render or for detail uncorrelated with the ground truth (noise, misplaced texture); negative where it is in
    counter-phase. Unlike the power ratio, noise does not raise it, so the two together separate detail kept
    (coherence) from power added (``hf_ratio − coherence²``: at least the power of the band that the ground truth
    does not explain, by Cauchy-Schwarz at most ``hf_ratio``). Inputs and errors as :func:`hf_ratio`."""
    return _scores(img, ref, cutoff, "high-frequency coherence")[1]


def hf_scores(img: np.ndarray, ref: np.ndarray, cutoff: float = CUTOFF) -> tuple[float, float]:
    """``(hf_ratio, hf_coherence)`` of ``img`` against ``ref`` from one transform of each (what ``eigs evaluate``
    reports for every view). Inputs and errors as :func:`hf_ratio`."""
    return _scores(img, ref, cutoff, "sharpness ratio and coherence")
