"""Sim(3) alignment, ATE and rotation errors against known transforms."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.metrics.trajectory import (
    Sim3,
    align_trajectory,
    extent,
    latent_relative_errors,
    motion_ratio_per_view,
    rotation_angle_deg,
    trajectory_accuracy,
    umeyama,
)
from eigs.sfm.canonical import canonical_transform


def rot(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    a = np.radians(deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k


def random_poses(n, rng, spread=1.0):
    out = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        out[i, :3, :3] = rot(rng.normal(size=3), rng.uniform(0, 180))
        out[i, :3, 3] = rng.normal(size=3) * spread
    return out


KNOWN = Sim3(2.5, rot([1, 2, 3], 40.0), np.array([0.3, -1.0, 2.0]))


def test_umeyama_recovers_known_transform():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(20, 3))
    dst = KNOWN.apply(src)
    est = umeyama(src, dst)
    assert est.scale == pytest.approx(2.5, rel=1e-12)
    np.testing.assert_allclose(est.R, KNOWN.R, atol=1e-12)
    np.testing.assert_allclose(est.t, KNOWN.t, atol=1e-12)


def test_umeyama_reflection_guard_and_noise():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(200, 3))
    dst = KNOWN.apply(src) + rng.normal(scale=1e-3, size=src.shape)
    est = umeyama(src, dst)
    assert np.linalg.det(est.R) == pytest.approx(1.0)
    assert rotation_angle_deg(est.R, KNOWN.R) < 0.01
    assert est.scale == pytest.approx(2.5, rel=1e-3)


def test_sim3_inverse_compose_and_poses_stay_rigid():
    rng = np.random.default_rng(2)
    x = rng.normal(size=(5, 3))
    np.testing.assert_allclose(KNOWN.inverse().apply(KNOWN.apply(x)), x, atol=1e-12)
    np.testing.assert_allclose(KNOWN.compose(KNOWN.inverse()).matrix(), np.eye(4), atol=1e-12)
    c2w = KNOWN.apply_c2w(random_poses(4, rng))
    r = c2w[:, :3, :3]
    np.testing.assert_allclose(np.einsum("nji,njk->nik", r, r), np.tile(np.eye(3), (4, 1, 1)), atol=1e-12)
    assert Sim3.from_dict(KNOWN.to_dict()).scale == KNOWN.scale


def test_trajectory_accuracy_exact_and_perturbed():
    rng = np.random.default_rng(3)
    gt = random_poses(30, rng)
    est = KNOWN.inverse().apply_c2w(gt)
    acc = trajectory_accuracy(est, gt)
    assert acc.method == "umeyama"
    assert acc.ate_rmse < 1e-10
    assert acc.rotation_errors_deg.max() < 1e-5
    # one centre off by 0.1 (gt units) in a set of 30: the RMSE is about 0.1/sqrt(30)
    gt2 = gt.copy()
    gt2[0, :3, 3] += [0.1, 0, 0]
    acc2 = trajectory_accuracy(est, gt2)
    assert 0.01 < acc2.ate_rmse < 0.03
    assert acc2.ate_percent == pytest.approx(100 * acc2.ate_rmse / extent(gt2[:, :3, 3]))


def test_collinear_trajectory_takes_line_from_centres_and_roll_from_orientations():
    """A slider: centres on a line, all cameras facing the same way (the rotation about the line is only
    determined by the orientations)."""
    n = 40
    gt = np.tile(np.eye(4), (n, 1, 1))
    gt[:, 0, 3] = np.linspace(0.1, 1.1, n)
    est = KNOWN.inverse().apply_c2w(gt)
    acc = trajectory_accuracy(est, gt)
    assert acc.method == "line+orientation"
    assert acc.ate_rmse < 1e-10
    assert acc.rotation_errors_deg.max() < 1e-5
    assert acc.sim.scale == pytest.approx(2.5)
    # noise on the estimated centres leaves a small ATE, and the rotation stays fixed by the orientations
    rng = np.random.default_rng(4)
    est_noisy = est.copy()
    est_noisy[:, :3, 3] += rng.normal(scale=1e-4, size=(n, 3))
    acc_n = trajectory_accuracy(est_noisy, gt)
    assert acc_n.ate_rmse < 1e-3
    assert acc_n.rotation_errors_deg.max() < 0.05  # the line direction tilts with the noise
    # a constant camera-to-rig rotation (uncalibrated hand-eye) shows in the rotation errors, not in the ATE
    est_he = est.copy()
    est_he[:, :3, :3] = est[:, :3, :3] @ rot([0.3, 1, 0.2], 0.5)
    acc_he = trajectory_accuracy(est_he, gt)
    assert acc_he.ate_rmse < 1e-10
    r = acc_he.rotation_errors_deg
    assert 0.1 < r.min() and r.max() <= 0.5 + 1e-9 and np.ptp(r) < 1e-6  # the roll part is absorbed
    # travelling the line backwards in the estimate is still aligned
    est_rev = KNOWN.inverse().apply_c2w(gt[::-1])[::-1]
    assert trajectory_accuracy(est_rev, gt).ate_rmse < 1e-10


def test_single_centre_falls_back_to_orientation_only():
    gt = np.tile(np.eye(4), (3, 1, 1))
    sim, method = align_trajectory(gt, gt)
    assert method == "orientation-only" and sim.scale == 1.0


def test_latent_relative_errors_copy_pose_fails_threshold():
    v, l_ = 3, 5
    gt = np.tile(np.eye(4), (v, l_, 1, 1))
    for k in range(l_):
        gt[:, k, :3, 3] = [0.01 * k, 0, 0]
        gt[:, k, :3, :3] = rot([0, 1, 0], 0.5 * k)
    est_good = KNOWN.inverse().apply_c2w(gt)
    r = latent_relative_errors(est_good, gt, scale=KNOWN.scale)
    assert np.nanmax(r["t_err"]) < 1e-12 and np.nanmax(r["r_err_deg"]) < 1e-5
    copy = np.repeat(gt[:, :1], l_, axis=1)
    rc = latent_relative_errors(copy, gt, scale=1.0)
    ratio = motion_ratio_per_view(rc["t_err"], rc["t_motion"], 1e-9)
    assert np.all(ratio > 0.25)
    ratio_r = motion_ratio_per_view(rc["r_err_deg"], rc["r_motion_deg"], 1e-9)
    assert np.all(ratio_r > 0.25)


def test_canonical_transform_centres_and_scales():
    rng = np.random.default_rng(5)
    c = rng.normal(size=(50, 3)) * 7 + [3, 4, 5]
    sim = canonical_transform(c)
    x = sim.apply(c)
    np.testing.assert_allclose(x.mean(0), 0, atol=1e-12)
    assert np.sqrt(np.mean(np.sum(x**2, 1))) == pytest.approx(1.0)
    np.testing.assert_allclose(sim.R, np.eye(3))
    same = canonical_transform(np.ones((4, 3)))
    assert same.scale == 1.0


def test_fill_within_views_interpolates_in_time_and_never_across_views():
    from eigs.sfm.poses import fill_within_views

    v, l_ = 3, 5
    c2w = np.tile(np.eye(4), (v, l_, 1, 1))
    t = np.tile(np.arange(l_) * 10, (v, 1)).astype(np.int64)
    for k in range(l_):
        c2w[:, k, :3, 3] = [k, 0, 0]
        c2w[:, k, :3, :3] = rot([0, 0, 1], 10.0 * k)
    known = np.ones((v, l_), bool)
    known[0, 2] = False  # interior: interpolated exactly (linear motion, constant angular rate)
    known[1, 4] = False  # beyond the last known latent: held
    known[2, :] = False  # no known latent: NaN
    filled, interp = fill_within_views(c2w, known, t)
    np.testing.assert_allclose(filled[0, 2], c2w[0, 2], atol=1e-12)
    np.testing.assert_allclose(filled[1, 4], c2w[1, 3], atol=1e-12)
    assert np.isnan(filled[2]).all()
    assert interp[0, 2] and interp[1, 4] and not interp[2].any() and interp.sum() == 2
