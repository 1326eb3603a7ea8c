"""How well a method's motion within the exposure matches the true camera motion (float64 throughout).

A method explains a blurry frame by moving the scene (or its camera) between the latent times k = 0..N of the
exposure. For view v the true camera moved from ``G_0`` to ``G_k`` (ground truth); its camera-frame delta
``M_k = G_0⁻¹ G_k`` is independent of the world frame up to scale. Rendering ``G_k``'s image from the reference camera
``P_0`` (the method's own, in the model frame) needs the scene moved by

    A_k = P_0 · M̃_k⁻¹ · P_0⁻¹,     M̃_k = M_k with its translation multiplied by s (model units per GT unit),

so the true displacement of a point x is ``A_k x − x``. Against it, for points x_j and every view and latent time:

- ``displacement_relative_error`` = ‖D − D*‖ / ‖D*‖ (Frobenius norms over all points, latents and views; 0 is exact,
  1 is as wrong as predicting no motion);
- ``displacement_cosine`` = ⟨D, D*⟩ / (‖D‖ ‖D*‖) (1: the right direction field up to scale);
- for methods with latent cameras (trajectory and fixed-pose methods), the camera deltas ``P_0⁻¹ P_k`` against
  ``M̃_k``: the mean rotation error (degrees) and the translation error relative to the true translation.

The scale s is the ratio of the RMS spread of the reference camera centres (model frame) to that of the ground-truth
centres at the same times. Ratios are NaN (with a reason) when the denominator is below ``EPS`` (no true motion).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

EPS = 1e-12


def rigid_inverse(c2w: np.ndarray) -> np.ndarray:
    """Inverse of rigid (…, 4, 4) transforms."""
    r, t = c2w[..., :3, :3], c2w[..., :3, 3:]
    out = np.zeros_like(c2w, dtype=np.float64)
    out[..., :3, :3] = np.swapaxes(r, -1, -2)
    out[..., :3, 3:] = -np.swapaxes(r, -1, -2) @ t
    out[..., 3, 3] = 1.0
    return out


def spread_scale(model_centres: np.ndarray, gt_centres: np.ndarray) -> float:
    """s = RMS distance of ``model_centres`` (M, 3) from their mean / the same for ``gt_centres`` (M, 3)."""
    a = np.asarray(model_centres, np.float64)
    b = np.asarray(gt_centres, np.float64)
    sa = math.sqrt(float(np.mean(np.sum((a - a.mean(0)) ** 2, axis=1)))) if len(a) else 0.0
    sb = math.sqrt(float(np.mean(np.sum((b - b.mean(0)) ** 2, axis=1)))) if len(b) else 0.0
    return sa / sb if sb > EPS else math.nan


def true_deltas(gt: np.ndarray, scale: float) -> np.ndarray:
    """(V, N, 4, 4) camera-frame deltas ``G_0⁻¹ G_k`` (k = 1..N) of the ground-truth latent poses ``gt`` (V, N+1, 4, 4),
    translations multiplied by ``scale``."""
    m = rigid_inverse(gt[:, :1]) @ gt[:, 1:]
    m[..., :3, 3] *= scale
    return m


def true_displacements(reference: np.ndarray, deltas: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(V, N, G, 3) true displacements ``A_k x − x`` of ``points`` (G, 3), with ``A_k = P_0 M̃_k⁻¹ P_0⁻¹`` from the
    reference cameras ``reference`` (V, 4, 4) and the scaled deltas ``deltas`` (V, N, 4, 4)."""
    a = reference[:, None] @ rigid_inverse(deltas) @ rigid_inverse(reference)[:, None]  # (V, N, 4, 4)
    x = np.asarray(points, np.float64)
    moved = np.einsum("vnij,gj->vngi", a[..., :3, :3], x) + a[..., None, :3, 3]
    return moved - x


def displacement_errors(pred: np.ndarray, true: np.ndarray) -> dict[str, float]:
    """Relative error and cosine of predicted displacements ``pred`` against ``true`` (same shape, …, 3)."""
    p = np.asarray(pred, np.float64).ravel()
    t = np.asarray(true, np.float64).ravel()
    nt, np_ = float(np.linalg.norm(t)), float(np.linalg.norm(p))
    rel = float(np.linalg.norm(p - t)) / nt if nt > EPS else math.nan
    cos = float(p @ t) / (np_ * nt) if np_ > EPS and nt > EPS else math.nan
    return {"displacement_relative_error": rel, "displacement_cosine": cos,
            "true_displacement_rms": nt / math.sqrt(max(t.size // 3, 1))}  # fmt: skip


def camera_errors(reference: np.ndarray, cameras: np.ndarray, deltas: np.ndarray) -> dict[str, float]:
    """Errors of the latent cameras ``cameras`` (V, N, 4, 4) as deltas from ``reference`` (V, 4, 4) against the true
    scaled deltas (V, N, 4, 4): mean rotation error (degrees) and ‖t − t*‖ / ‖t*‖ over all latents."""
    d = rigid_inverse(reference)[:, None] @ cameras
    r = np.swapaxes(d[..., :3, :3], -1, -2) @ deltas[..., :3, :3]
    # the angle as atan2(sin, cos): accurate near 0, where arccos of the trace loses half the digits
    cos = (np.trace(r, axis1=-2, axis2=-1) - 1) / 2
    sin = 0.5 * np.linalg.norm(np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                                         r[..., 1, 0] - r[..., 0, 1]], -1), axis=-1)  # fmt: skip
    angle = np.degrees(np.arctan2(sin, cos))
    t, ts = d[..., :3, 3].ravel(), deltas[..., :3, 3].ravel()
    nt = float(np.linalg.norm(ts))
    return {
        "rotation_error_deg": float(angle.mean()) if angle.size else math.nan,
        "translation_relative_error": float(np.linalg.norm(t - ts)) / nt if nt > EPS else math.nan,
    }


def motion_errors(
    points: np.ndarray,
    displacement: np.ndarray,
    reference: np.ndarray,
    gt: np.ndarray,
    views: np.ndarray,
    cameras: np.ndarray | None = None,
) -> dict[str, Any]:
    """All motion errors of one run. ``points`` (G, 3), ``displacement`` (V, N, G, 3), ``reference`` (V, 4, 4) and
    ``cameras`` (V, N, 4, 4) as the run's motion file holds them; ``gt`` (V, N+1, 4, 4) ground-truth latent poses at
    the same times; ``views`` (V,) bool, the views to score (those with finite reference and ground truth are kept)."""
    ok = np.asarray(views, bool) & np.all(np.isfinite(reference), axis=(-2, -1))
    ok &= np.all(np.isfinite(gt), axis=(-3, -2, -1))
    out: dict[str, Any] = {"views": int(ok.sum())}
    if not ok.any():
        out["reason"] = "no view has a finite reference pose and ground truth"
        return out
    scale = spread_scale(reference[ok, :3, 3], gt[ok, 0, :3, 3]) if ok.sum() > 1 else math.nan
    out["scale"] = scale
    if not math.isfinite(scale):
        out["reason"] = "the scale between model and ground truth is undefined (fewer than 2 distinct cameras)"
        return out
    deltas = true_deltas(gt[ok], scale)
    true = true_displacements(reference[ok], deltas, points)
    out.update(displacement_errors(displacement[ok], true))
    if cameras is not None:
        out.update(camera_errors(reference[ok], cameras[ok], deltas))
    return out
