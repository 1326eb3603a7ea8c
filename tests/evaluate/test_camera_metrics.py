"""Refined training cameras scored against the ground truth (eigs.evaluate.core.camera_metrics, the run folder's
cameras.npz from eigs.artifacts.cameras): known corrections give known errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eigs.artifacts.cameras import RefinedCameras, read_refined_cameras, write_refined_cameras
from eigs.artifacts.edi import read_edi
from eigs.errors import EigsError
from eigs.evaluate.core import camera_metrics
from eigs.scene import read_scene
from eigs.scene.truth import latent_poses_at


def _rot_about_centre(c2w: np.ndarray, deg: float) -> np.ndarray:
    """``c2w`` turned by ``deg`` about its own y axis (the centre stays)."""
    a = math.radians(deg)
    r = np.eye(4)
    r[0, 0], r[0, 2], r[2, 0], r[2, 2] = math.cos(a), math.sin(a), -math.sin(a), math.cos(a)
    return c2w @ r


def _similarity(c2w: np.ndarray, scale: float) -> np.ndarray:
    """Every pose moved by one Sim(3): rotation 40° about z, ``scale``, a translation (rigid poses stay rigid)."""
    a = math.radians(40.0)
    R = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1.0]])
    out = c2w.copy()
    out[..., :3, :3] = R @ c2w[..., :3, :3]
    out[..., :3, 3] = scale * c2w[..., :3, 3] @ R.T + np.array([0.3, -1.0, 2.0])
    return out


def test_cameras_refined_to_the_truth_score_zero_and_the_unrefined_errors_are_the_known_ones(toy, tmp_path):
    scene = read_scene(toy.scene, events=False)
    times = read_edi(toy.edi).timestamps_us
    gt0 = latent_poses_at(scene, times)[0][:, 0]  # (V, 4, 4) the reference times' true cameras
    v = gt0.shape[0]
    before = gt0.copy()
    before[2] = _rot_about_centre(before[2], 3.0)
    before[5] = _rot_about_centre(before[5], -1.5)
    views = np.ones(v, bool)
    views[7] = False  # a view training never drew: not scored, even with a wrong camera
    before[7] = _rot_about_centre(before[7], 30.0)
    cams = RefinedCameras(method="3dgs", before=_similarity(before, 2.5), after=_similarity(gt0, 2.5),
                          twist=np.zeros((v, 6)), views=views)  # fmt: skip
    write_refined_cameras(cams, tmp_path / "cameras.npz")
    back = read_refined_cameras(tmp_path)
    np.testing.assert_array_equal(back.before, cams.before)
    np.testing.assert_array_equal(back.views, views)

    got = camera_metrics(tmp_path, scene, times)
    assert got["views"] == v - 1
    # the centres are the truth's under one similarity: both ATEs vanish; rotation errors are the turns given
    assert got["after"]["ate_percent_of_extent"] == pytest.approx(0.0, abs=1e-9)
    assert got["before"]["ate_percent_of_extent"] == pytest.approx(0.0, abs=1e-9)
    assert got["after"]["rotation_error_deg_max"] == pytest.approx(0.0, abs=1e-5)
    assert got["before"]["rotation_error_deg_max"] == pytest.approx(3.0, abs=1e-6)
    assert got["before"]["rotation_error_deg_median"] == pytest.approx(0.0, abs=1e-5)


def test_no_file_no_scores_and_a_damaged_file_is_named(toy, tmp_path):
    scene = read_scene(toy.scene, events=False)
    times = read_edi(toy.edi).timestamps_us
    assert camera_metrics(tmp_path, scene, times) is None  # the run did not refine its cameras
    v = times.shape[0]
    bad = RefinedCameras(method="3dgs", before=np.tile(np.eye(4), (v, 1, 1)), after=np.full((v, 4, 4), np.nan),
                         twist=np.zeros((v, 6)), views=np.ones(v, bool))  # fmt: skip
    with pytest.raises(EigsError, match=r"cameras.npz.*after has NaN/Inf"):
        write_refined_cameras(bad, tmp_path / "cameras.npz")
    assert not (tmp_path / "cameras.npz").exists()
    (tmp_path / "cameras.npz").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(EigsError, match=r"cameras.npz: unreadable refined-cameras file"):
        camera_metrics(tmp_path, scene, times)
