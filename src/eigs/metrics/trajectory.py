"""Similarity alignment of camera trajectories and the accuracy figures derived from it.

Own implementation of the closed-form Umeyama (1991) least-squares similarity, plus a variant for collinear
trajectories (a slider) whose rotation comes from the camera orientations. All poses are camera-to-world 4×4
matrices in OpenCV axes; centres are (N, 3) in scene units.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

COLLINEAR_RATIO = 1e-3  # second / first singular value of the centred positions below which they count as a line


@dataclass(frozen=True)
class Sim3:
    """x ↦ scale · R x + t. ``R``: (3, 3) rotation; ``t``: (3,); ``scale`` > 0."""

    scale: float
    R: np.ndarray
    t: np.ndarray

    @staticmethod
    def identity() -> Sim3:
        return Sim3(1.0, np.eye(3), np.zeros(3))

    def matrix(self) -> np.ndarray:
        """(4, 4) homogeneous matrix [sR t; 0 1]."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.R
        m[:3, 3] = self.t
        return m

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Map points ``x``: (..., 3) → (..., 3)."""
        return self.scale * np.asarray(x, np.float64) @ self.R.T + self.t

    def apply_c2w(self, c2w: np.ndarray) -> np.ndarray:
        """Map camera-to-world poses (..., 4, 4): centre ↦ sim(centre), rotation ↦ R·R_c2w (stays rigid)."""
        c2w = np.asarray(c2w, np.float64)
        out = c2w.copy()
        out[..., :3, :3] = self.R @ c2w[..., :3, :3]
        out[..., :3, 3] = self.apply(c2w[..., :3, 3])
        return out

    def inverse(self) -> Sim3:
        return Sim3(1.0 / self.scale, self.R.T, -(self.R.T @ self.t) / self.scale)

    def compose(self, other: Sim3) -> Sim3:
        """``self ∘ other`` (apply ``other`` first)."""
        return Sim3(self.scale * other.scale, self.R @ other.R, self.scale * self.R @ other.t + self.t)

    def to_dict(self) -> dict:
        return {"scale": float(self.scale), "R": self.R.tolist(), "t": self.t.tolist()}

    @staticmethod
    def from_dict(d: dict) -> Sim3:
        return Sim3(float(d["scale"]), np.asarray(d["R"], np.float64), np.asarray(d["t"], np.float64))


def project_to_rotation(m: np.ndarray) -> np.ndarray:
    """Nearest rotation (Frobenius) to a (3, 3) matrix."""
    u, _, vt = np.linalg.svd(m)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def umeyama(src: np.ndarray, dst: np.ndarray, *, with_scale: bool = True) -> Sim3:
    """Least-squares similarity with ``dst ≈ scale · R src + t`` (Umeyama 1991, closed form).

    ``src``, ``dst``: (N, 3), N ≥ 3 non-collinear points for a unique answer (collinear points leave the
    rotation about their line undetermined; use :func:`align_trajectory`).
    """
    src = np.asarray(src, np.float64)
    dst = np.asarray(dst, np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3 or src.shape[0] < 1:
        raise ValueError(f"umeyama needs two (N, 3) arrays of equal shape, got {src.shape} and {dst.shape}")
    mu_s, mu_d = src.mean(0), dst.mean(0)
    xs, xd = src - mu_s, dst - mu_d
    n = src.shape[0]
    var_s = float((xs**2).sum()) / n
    cov = xd.T @ xs / n
    u, sig, vt = np.linalg.svd(cov)
    s = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0:
        s[2, 2] = -1.0
    R = u @ s @ vt
    scale = float(np.trace(np.diag(sig) @ s) / var_s) if with_scale and var_s > 0 else 1.0
    t = mu_d - scale * R @ mu_s
    return Sim3(scale, R, t)


def is_collinear(x: np.ndarray, ratio: float = COLLINEAR_RATIO) -> bool:
    """True when points ``x`` (N, 3) lie (almost) on a line or a point: σ₂ ≤ ratio · σ₁ of the centred points."""
    x = np.asarray(x, np.float64)
    if x.shape[0] < 3:
        return True
    sv = np.linalg.svd(x - x.mean(0), compute_uv=False)
    return bool(sv[0] == 0 or sv[1] <= ratio * sv[0])


def rotation_from_orientations(src_R: np.ndarray, dst_R: np.ndarray) -> np.ndarray:
    """Rotation Q minimising Σ‖Q·src_R_i − dst_R_i‖² (chordal mean of dst_R_i · src_R_iᵀ). Shapes (N, 3, 3)."""
    m = np.einsum("nij,nkj->ik", np.asarray(dst_R, np.float64), np.asarray(src_R, np.float64))
    return project_to_rotation(m)


def _rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    v = np.cross(a, b)
    s, c = float(np.linalg.norm(v)), float(np.dot(a, b))
    if s < 1e-15:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])  # 180° about any perpendicular
        return _rotation_about(perp / np.linalg.norm(perp), np.pi)
    return _rotation_about(v / s, np.arctan2(s, c))


def _principal_direction(x: np.ndarray) -> np.ndarray:
    return np.linalg.svd(x - x.mean(0), full_matrices=False)[2][0]


def align_trajectory(src_c2w: np.ndarray, dst_c2w: np.ndarray, *, with_scale: bool = True) -> tuple[Sim3, str]:
    """Sim(3) mapping the ``src`` camera centres onto ``dst`` (both (N, 4, 4) c2w).

    Returns ``(sim, method)``: ``"umeyama"`` on the centres in general. For a collinear ``dst`` trajectory (a
    slider) the centres fix only the direction of the line, not the rotation about it: ``"line+orientation"``
    maps the ``src`` line direction onto the ``dst`` one and takes the remaining rotation about the line from the
    camera orientations (closed form), then scale and translation from the centres. The centre residuals (ATE)
    are then those of a centres-only fit, and the rotation errors are meaningful. With fewer than 2 distinct
    ``src`` or ``dst`` centres the whole rotation comes from the orientations and the scale is 1:
    ``"orientation-only"``.
    """
    src_c2w = np.asarray(src_c2w, np.float64)
    dst_c2w = np.asarray(dst_c2w, np.float64)
    cs, cd = src_c2w[:, :3, 3], dst_c2w[:, :3, 3]
    if not is_collinear(cd):
        return umeyama(cs, cd, with_scale=with_scale), "umeyama"
    mu_s, mu_d = cs.mean(0), cd.mean(0)
    xs, xd = cs - mu_s, cd - mu_d
    tiny = 1e-12 * max(1.0, float(np.abs(cs).max()), float(np.abs(cd).max()))
    if np.linalg.norm(xs, axis=1).max() <= tiny or np.linalg.norm(xd, axis=1).max() <= tiny:
        R = rotation_from_orientations(src_c2w[:, :3, :3], dst_c2w[:, :3, :3])
        return Sim3(1.0, R, mu_d - R @ mu_s), "orientation-only"
    de, dg = _principal_direction(cs), _principal_direction(cd)
    if np.dot(xs @ de, xd @ dg) < 0:  # orient the src direction like the travel along dst
        de = -de
    R0 = _rotation_between(de, dg)
    # rotation about dg maximising Σ tr(R_dst_iᵀ · Rot(dg, φ) · R0 · R_src_i) = tr(Rot(dg, φ) · A)
    A = R0 @ np.einsum("nij,nkj->ik", src_c2w[:, :3, :3], dst_c2w[:, :3, :3])
    a = float(np.trace(A) - dg @ A @ dg)
    kx = np.array([[0, -dg[2], dg[1]], [dg[2], 0, -dg[0]], [-dg[1], dg[0], 0]])
    b = float(np.trace(kx @ A))
    R = _rotation_about(dg, np.arctan2(b, a)) @ R0
    scale = float(np.einsum("ni,ni->", xd, xs @ R.T) / float((xs**2).sum())) if with_scale else 1.0
    return Sim3(scale, R, mu_d - scale * R @ mu_s), "line+orientation"


def rotation_angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Geodesic angle between rotations (..., 3, 3) in degrees."""
    rel = np.einsum("...ji,...jk->...ik", np.asarray(Ra, np.float64), np.asarray(Rb, np.float64))
    c = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def extent(centres: np.ndarray) -> float:
    """Largest distance between two of the (N, 3) points (0 for fewer than 2)."""
    c = np.asarray(centres, np.float64)
    if c.shape[0] < 2:
        return 0.0
    if c.shape[0] > 4000:  # the diameter lies on the convex hull
        from scipy.spatial import ConvexHull

        try:
            c = c[ConvexHull(c).vertices]
        except Exception:  # degenerate (flat/collinear) sets: fall back to all points in chunks
            pass
    best = 0.0
    for i in range(0, c.shape[0], 1024):
        d = np.linalg.norm(c[i : i + 1024, None, :] - c[None, :, :], axis=-1)
        best = max(best, float(d.max()))
    return best


@dataclass
class Accuracy:
    """Accuracy of estimated poses against ground truth after Sim(3) alignment (scene units, degrees)."""

    sim: Sim3  # estimated → ground-truth frame
    method: str
    ate_rmse: float
    ate_percent: float  # of ``extent``
    extent: float
    centre_errors: np.ndarray  # (N,)
    rotation_errors_deg: np.ndarray  # (N,)

    def summary(self) -> dict:
        r = self.rotation_errors_deg
        e = self.centre_errors
        return {
            "alignment": self.method,
            "sim3_est_to_gt": self.sim.to_dict(),
            "n": int(e.size),
            "ate_rmse": float(self.ate_rmse),
            "ate_percent_of_extent": float(self.ate_percent),
            "extent": float(self.extent),
            "centre_error_median": float(np.median(e)) if e.size else float("nan"),
            "centre_error_max": float(e.max()) if e.size else float("nan"),
            "rotation_error_deg_mean": float(r.mean()) if r.size else float("nan"),
            "rotation_error_deg_median": float(np.median(r)) if r.size else float("nan"),
            "rotation_error_deg_max": float(r.max()) if r.size else float("nan"),
        }


def trajectory_accuracy(est_c2w: np.ndarray, gt_c2w: np.ndarray, gt_extent: float | None = None) -> Accuracy:
    """Sim(3)-align ``est_c2w`` (N, 4, 4) to ``gt_c2w`` (N, 4, 4); ATE = RMSE of the aligned centres.

    ``gt_extent``: scene extent for the percentage (default: largest distance between two ``gt`` centres).
    """
    sim, method = align_trajectory(est_c2w, gt_c2w)
    aligned = sim.apply_c2w(est_c2w)
    err = np.linalg.norm(aligned[:, :3, 3] - gt_c2w[:, :3, 3], axis=1)
    ate = float(np.sqrt(np.mean(err**2))) if err.size else float("nan")
    ext = extent(gt_c2w[:, :3, 3]) if gt_extent is None else float(gt_extent)
    rot = rotation_angle_deg(aligned[:, :3, :3], gt_c2w[:, :3, :3])
    return Accuracy(sim, method, ate, 100.0 * ate / ext if ext > 0 else float("nan"), ext, err, rot)


def relative_to_first(c2w: np.ndarray) -> np.ndarray:
    """Poses relative to latent 0 of their view: (V, L, 4, 4) → (V, L, 4, 4) with T_0⁻¹ T_k."""
    c2w = np.asarray(c2w, np.float64)
    inv0 = np.linalg.inv(c2w[:, :1])
    return inv0 @ c2w


def latent_relative_errors(
    est_c2w: np.ndarray, gt_c2w: np.ndarray, scale: float, valid: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """Errors of latent poses relative to latent 0, per view, against the true intra-exposure motion.

    ``est_c2w``, ``gt_c2w``: (V, L, 4, 4); ``scale``: estimated → ground-truth units (from the Sim(3));
    ``valid``: (V, L) bool, poses to compare (latent 0 must be valid for a view to count).
    Returns (V, L) arrays ``t_err`` (scene units), ``r_err_deg``, ``t_motion`` (‖true relative translation‖),
    ``r_motion_deg`` (true relative rotation angle), with NaN where not comparable.
    """
    rel_e = relative_to_first(est_c2w)
    rel_g = relative_to_first(gt_c2w)
    t_err = np.linalg.norm(scale * rel_e[..., :3, 3] - rel_g[..., :3, 3], axis=-1)
    r_err = rotation_angle_deg(rel_e[..., :3, :3], rel_g[..., :3, :3])
    t_mot = np.linalg.norm(rel_g[..., :3, 3], axis=-1)
    r_mot = rotation_angle_deg(np.broadcast_to(np.eye(3), rel_g[..., :3, :3].shape), rel_g[..., :3, :3])
    if valid is not None:
        ok = np.asarray(valid, bool) & np.asarray(valid, bool)[:, :1]
        t_err = np.where(ok, t_err, np.nan)
        r_err = np.where(ok, r_err, np.nan)
    return {"t_err": t_err, "r_err_deg": r_err, "t_motion": t_mot, "r_motion_deg": r_mot}


def motion_ratio_per_view(err: np.ndarray, motion: np.ndarray, min_motion: float) -> np.ndarray:
    """Per view: median over k ≥ 1 of the error divided by the view's intra-exposure motion (the largest true
    motion over its latents). NaN for views whose motion is below ``min_motion`` or without comparable latents.
    ``err``, ``motion``: (V, L). Copying latent 0 to every slot scores about 0.5–0.6 on a linear motion."""
    v = err.shape[0]
    out = np.full(v, np.nan)
    for i in range(v):
        m = float(np.nanmax(motion[i, 1:])) if motion.shape[1] > 1 else 0.0
        e = err[i, 1:]
        e = e[np.isfinite(e)]
        if m > min_motion and e.size:
            out[i] = float(np.median(e)) / m
    return out
