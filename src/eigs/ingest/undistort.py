"""Undistortion to a pinhole camera with the same K and size (OpenCV radial-tangential model k1 k2 p1 p2 k3).

Frames are remapped (bilinear, black outside); events go through a per-pixel lookup table built from the same
model: each sensor pixel centre is undistorted (iteratively, then verified by re-distorting it to within
:data:`ROUNDTRIP_TOL_PX`), projected with K and rounded to the nearest pixel. Events whose pixel lands outside
the image, or whose undistortion does not converge, are dropped and counted.
"""

from __future__ import annotations

import numpy as np

ROUNDTRIP_TOL_PX = 1e-3


def _to_cv(K: np.ndarray) -> np.ndarray:
    """Our K (pixel centres at j + 0.5) → OpenCV K (centres at integers)."""
    k = np.array(K, dtype=np.float64, copy=True)
    k[0, 2] -= 0.5
    k[1, 2] -= 0.5
    return k


def distort_normalized(xn: np.ndarray, yn: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Apply the OpenCV radial-tangential model to normalised coordinates (N,) → distorted normalised (N,)."""
    k1, k2, p1, p2, k3 = (float(v) for v in dist)
    r2 = xn * xn + yn * yn
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


class Undistorter:
    """Undistortion of one camera: ``K`` (3, 3) ours, ``dist`` (5,), sensor ``width`` × ``height``.

    ``event_lut``: (H·W,) int32 flat index ``y·W + x`` of the undistorted pixel for each sensor pixel, −1 when the
    event is dropped.
    """

    def __init__(self, K: np.ndarray, dist: np.ndarray, width: int, height: int):
        import cv2

        self.K, self.dist = np.asarray(K, np.float64), np.asarray(dist, np.float64)
        self.width, self.height = int(width), int(height)
        kcv = _to_cv(self.K)
        fx, fy, cx, cy = kcv[0, 0], kcv[1, 1], kcv[0, 2], kcv[1, 2]
        jj, ii = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
        pts = np.stack([jj.ravel(), ii.ravel()], axis=-1)[:, None, :]
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-14)
        und = cv2.undistortPoints(pts, kcv, self.dist, None, None, None, crit)[:, 0, :]
        xn, yn = und[:, 0], und[:, 1]
        xd, yd = distort_normalized(xn, yn, self.dist)
        err = np.hypot(xd * fx + cx - pts[:, 0, 0], yd * fy + cy - pts[:, 0, 1])
        u = np.rint(xn * fx + cx)
        v = np.rint(yn * fy + cy)
        ok = np.isfinite(err) & (err <= ROUNDTRIP_TOL_PX) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        lut = np.full(width * height, -1, dtype=np.int32)
        lut[ok] = (v[ok] * width + u[ok]).astype(np.int32)
        self.event_lut = lut
        self.n_unconverged = int(np.count_nonzero(~(np.isfinite(err) & (err <= ROUNDTRIP_TOL_PX))))
        self._maps = cv2.initUndistortRectifyMap(kcv, self.dist, None, kcv, (width, height), cv2.CV_32FC1)

    def events(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N,) uint16 sensor x, y → (keep (N,) bool, x' (M,) uint16, y' (M,) uint16) for the kept events."""
        flat = self.event_lut[y.astype(np.int64) * self.width + x]
        keep = flat >= 0
        flat = flat[keep]
        return keep, (flat % self.width).astype(np.uint16), (flat // self.width).astype(np.uint16)

    def frames(self, frames: np.ndarray) -> np.ndarray:
        """(V, H, W, C) uint8 → (V, H, W, C) uint8 remapped to the pinhole camera (bilinear, black outside)."""
        import cv2

        out = np.empty_like(frames)
        m1, m2 = self._maps
        for i in range(frames.shape[0]):
            r = cv2.remap(frames[i], m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            out[i] = r.reshape(frames.shape[1:])
        return out
