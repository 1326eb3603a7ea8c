"""The sfm stage on scenes rendered by the test ray caster: given mode, COLMAP mode, failure handling."""

from __future__ import annotations

import dataclasses
import json
import shutil

import cv2
import numpy as np
import pycolmap
import pytest

from eigs.artifacts.edi import latent_png_name
from eigs.artifacts.poses import METHOD_FALLBACK, METHOD_GIVEN, METHOD_REGISTERED, read_poses, read_test_cameras
from eigs.cli import main
from eigs.errors import EigsError
from eigs.metrics.trajectory import Sim3, extent, umeyama
from eigs.sfm.colmap import c2w_of
from eigs.sfm.run import SfmConfig, run_sfm

from . import raycast as rc
from .fixtures import make_scene


@pytest.fixture(scope="module")
def scene8(tmp_path_factory):
    """8 views × 3 latents (2 bins), 128×96, 3 novel views; ground-truth poses."""
    return make_scene(tmp_path_factory.mktemp("rc8"), views=8, bins=2)


def canonical_of(poses) -> Sim3:
    m = poses.canonical
    s = float(np.cbrt(np.linalg.det(m[:3, :3])))
    return Sim3(s, m[:3, :3] / s, m[:3, 3])


def test_given_mode_reproduces_poses_and_triangulates_on_the_surfaces(scene8, tmp_path):
    out = tmp_path / "sfm"
    assert main(["sfm", str(scene8["scene"]), str(scene8["edi"]), "-o", str(out)]) == 0  # auto → given
    report = json.loads((out / "report.json").read_text())
    assert report["mode"] == "given"
    poses = read_poses(out)
    canon = canonical_of(poses)
    gt = scene8["latent"]
    np.testing.assert_allclose(poses.c2w, canon.apply_c2w(gt), atol=1e-12)
    assert poses.registered.all() and not poses.interpolated.any()
    # canonical frame: centres centred, RMS radius 1
    c = poses.c2w[..., :3, 3].reshape(-1, 3)
    np.testing.assert_allclose(c.mean(0), 0, atol=1e-12)
    assert np.sqrt((c**2).sum(1).mean()) == pytest.approx(1.0)
    # the standard model opens in pycolmap, in the canonical frame, with the poses unchanged
    rec = pycolmap.Reconstruction(str(out))
    assert {p.name for p in out.iterdir()} >= {"cameras.bin", "images.bin", "points3D.bin", "poses.h5"}
    for im in rec.images.values():
        v, k = int(im.name[1:5]), int(im.name[7:9])
        np.testing.assert_allclose(c2w_of(im), poses.c2w[v, k], atol=1e-9)
    xyz = np.array([p.xyz for p in rec.points3D.values()])
    assert len(xyz) > 300
    d = rc.surface_distance(canon.inverse().apply(xyz))
    ext = extent(gt.reshape(-1, 4, 4)[:, :3, 3])
    assert np.median(d) <= 0.005 * ext
    # test cameras: exact ground truth in the canonical frame
    tc = read_test_cameras(out)
    assert len(tc) == 11 and np.all(tc.method == METHOD_GIVEN)
    np.testing.assert_allclose(tc.c2w, canon.apply_c2w(scene8["sharp_c2w"]), atol=1e-12)
    # the reported alignment of the estimate onto ground truth is the inverse of the canonical transform
    # (given mode places the ground truth in the canonical frame), and the ATE after it is zero
    est_to_gt = Sim3.from_dict(report["accuracy"]["sim3_est_to_gt"])
    np.testing.assert_allclose(est_to_gt.compose(canon).matrix(), np.eye(4), atol=1e-9)
    assert 0 <= report["accuracy"]["ate_rmse"] < 1e-9
    # init from this model
    ply = tmp_path / "init.ply"
    assert main(["init", str(out), "-o", str(ply), "--min-points", "10"]) == 0
    from eigs.artifacts.gaussians import read_gaussian_ply

    cloud = read_gaussian_ply(ply)
    assert len(cloud) == len(xyz)
    np.testing.assert_allclose(cloud.means, xyz, atol=1e-5)


def test_colmap_mode_registers_latents_and_test_cameras(scene8, tmp_path):
    out = tmp_path / "sfm"
    rep = run_sfm(scene8["scene"], scene8["edi"], out, cfg=SfmConfig(mode="colmap"))
    assert rep["registration"]["fraction"] == 1.0
    acc = rep["accuracy"]
    assert acc["ate_percent_of_extent"] < 1.0
    assert acc["rotation_error_deg_median"] < 0.5
    rel = acc["relative_latent"]
    assert rel["translation_ratio_median"] < 0.25 and rel["rotation_ratio_median"] < 0.25
    tc = read_test_cameras(out)
    assert np.all(tc.method == METHOD_REGISTERED)
    assert np.median(tc.reprojection_error_px) <= 0.5
    # registered test cameras agree with the Sim(3)-mapped ground truth
    est_to_gt = Sim3.from_dict(acc["sim3_est_to_gt"])
    mapped = est_to_gt.inverse().apply_c2w(scene8["sharp_c2w"])
    assert np.median(np.linalg.norm(mapped[:, :3, 3] - tc.c2w[:, :3, 3], axis=1)) < 0.01  # canonical units
    poses = read_poses(out)
    assert poses.mode == "colmap" and poses.registered.all()
    assert (out / "report.png").is_file()
    check = rep["self_check"]
    assert check["passed"] and check["enforced"] and check["failed_views"] == []
    assert max(check["path_error"]) < check["limits"]["path_error"]


def test_self_check_drops_a_failed_view_and_stops_on_a_broken_path(scene8, tmp_path, monkeypatch):
    """The stage acts on the self-check's verdict (eigs.sfm.selfcheck, tested on its own in test_selfcheck.py):
    a failed view loses its poses like an unregistered one; a failed reconstruction stops the stage with one line
    and writes nothing; with self_check off it is reported only. (Test cameras are not registered: they play no part
    in the check, and registering them is a third of each stage run.)"""
    import eigs.sfm.selfcheck as sc

    real = sc.self_check

    def one_view_off(c2w, registered, t_us, models=None):
        out = real(c2w, registered, t_us, models)
        out.failed_views = [3]
        return out

    on = SfmConfig(mode="colmap", register_test_cameras=False)
    monkeypatch.setattr(sc, "self_check", one_view_off)
    out = tmp_path / "dropped"
    rep = run_sfm(scene8["scene"], scene8["edi"], out, cfg=on)
    poses = read_poses(out)
    assert not poses.valid[3].any() and poses.valid[np.arange(8) != 3].all()
    assert rep["registration"]["dropped_by_self_check"] == [3] and 3 in rep["registration"]["views_without_all_poses"]

    def broken(c2w, registered, t_us, models=None):
        out = real(c2w, registered, t_us, models)
        out.passed, out.reasons = False, ["the camera path breaks: (made up by the test)"]
        return out

    monkeypatch.setattr(sc, "self_check", broken)
    out = tmp_path / "stopped"
    with pytest.raises(EigsError, match=r"SfM self-check failed: the camera path breaks.*self_check: false"):
        run_sfm(scene8["scene"], scene8["edi"], out, cfg=on)
    assert not out.exists()
    rep = run_sfm(scene8["scene"], scene8["edi"], out, cfg=dataclasses.replace(on, self_check=False))
    assert rep["self_check"]["passed"] is False and rep["self_check"]["enforced"] is False
    assert read_poses(out).valid.all()


def test_unregistered_latents_are_interpolated_within_their_view(scene8, tmp_path):
    """Two latent frames replaced by noise do not register: they are interpolated from their own view, the
    test cameras fall back to the Sim(3) without registration, and a strict fraction stops with remedies."""
    src = scene8["dir"]
    latent = tmp_path / "latent"
    shutil.copytree(src / "latent", latent)
    rng = np.random.default_rng(0)
    bad = [(2, 1), (5, 2)]
    for v, k in bad:
        cv2.imwrite(str(latent / latent_png_name(v, k)), rng.integers(0, 256, (96, 128, 3), dtype=np.uint8))
    cfg = SfmConfig(mode="colmap", register_test_cameras=False)
    rep = run_sfm(scene8["scene"], scene8["edi"], tmp_path / "sfm", latent_dir=latent, cfg=cfg)
    assert sorted(rep["registration"]["unregistered"]) == sorted(latent_png_name(v, k) for v, k in bad)
    poses = read_poses(tmp_path / "sfm")
    for v, k in bad:
        assert not poses.registered[v, k] and poses.interpolated[v, k]
    assert poses.valid.all()
    # interpolated poses stay within the view's motion (a few % of the canonical radius)
    assert np.linalg.norm(poses.c2w[2, 1, :3, 3] - poses.c2w[2, 0, :3, 3]) < 0.1
    # fallback test cameras: the true sharp-image poses carried into the canonical frame by the similarity that
    # maps the true latent centres onto the registered ones (fitted here, independently of the stage)
    reg = poses.registered
    gt_to_model = umeyama(scene8["latent"][reg][:, :3, 3], poses.c2w[reg][:, :3, 3])
    expected = gt_to_model.apply_c2w(scene8["sharp_c2w"])
    tc = read_test_cameras(tmp_path / "sfm")
    assert np.all(tc.method == METHOD_FALLBACK) and np.all(np.isnan(tc.reprojection_error_px))
    assert np.all(np.isfinite(tc.c2w))
    assert np.median(np.linalg.norm(tc.c2w[:, :3, 3] - expected[:, :3, 3], axis=1)) < 0.01  # canonical units

    strict = SfmConfig(mode="colmap", register_test_cameras=False, min_registered_fraction=1.0)
    with pytest.raises(
        EigsError, match=r"only 22 of 24 latent frames registered.*v0002_k01.png.*Remedies: more latent"
    ):
        run_sfm(scene8["scene"], scene8["edi"], tmp_path / "strict", latent_dir=latent, cfg=strict)
    assert not (tmp_path / "strict").exists()


def test_nothing_reconstructed_says_so(scene8, tmp_path):
    latent = tmp_path / "latent"
    shutil.copytree(scene8["dir"] / "latent", latent)
    for p in latent.iterdir():
        cv2.imwrite(str(p), np.full((96, 128, 3), 128, np.uint8))
    with pytest.raises(EigsError, match="COLMAP reconstructed nothing from 24 latent frames.*Remedies"):
        run_sfm(scene8["scene"], scene8["edi"], tmp_path / "sfm", latent_dir=latent, cfg=SfmConfig(mode="colmap"))


def test_input_errors(scene8, tmp_path, capsys):
    from eigs.scene import read_scene, write_scene

    # given mode on a scene without poses
    s = read_scene(scene8["scene"], events=False)
    s.poses = None
    write_scene(s, tmp_path / "noposes.h5")
    with pytest.raises(EigsError, match="--mode given: the scene has no latent poses"):
        run_sfm(tmp_path / "noposes.h5", scene8["edi"], tmp_path / "o", cfg=SfmConfig(mode="given"))
    # EDI of another scene (view count)
    s2 = read_scene(scene8["scene"], events=False)
    s2.frames.blurry = s2.frames.blurry[:5]
    s2.frames.exposure_us = s2.frames.exposure_us[:5]
    s2.poses.latent_c2w, s2.poses.latent_t_us = s2.poses.latent_c2w[:5], s2.poses.latent_t_us[:5]
    s2.sharp = None
    write_scene(s2, tmp_path / "five.h5")
    with pytest.raises(EigsError, match="EDI has 8 views but the scene 5"):
        run_sfm(tmp_path / "five.h5", scene8["edi"], tmp_path / "o")
    # latent frames of the wrong size
    latent = tmp_path / "latent"
    latent.mkdir()
    for v in range(8):
        for k in range(3):
            cv2.imwrite(str(latent / latent_png_name(v, k)), np.zeros((10, 12, 3), np.uint8))
    with pytest.raises(EigsError, match="latent frame is 12×10, the camera is 128×96"):
        run_sfm(scene8["scene"], scene8["edi"], tmp_path / "o", latent_dir=latent)
    # the CLI prints one line and exits 2
    assert main(["sfm", str(tmp_path / "absent.h5"), str(scene8["edi"]), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "eigs sfm: error:" in err and "no such scene file" in err
    assert main(["init", str(tmp_path), "-o", str(tmp_path / "x.ply")]) == 2
    assert "no points3D.bin" in capsys.readouterr().err


def test_sharp_views_and_missing_pngs(tmp_path):
    """A view EDI marks sharp contributes one image whose pose fills every slot; without latent PNGs the stage
    writes them from edi.h5."""
    d = make_scene(tmp_path, views=6, bins=2, novel=0, sharp_views=(3,), write_latent_pngs=False)
    rep = run_sfm(d["scene"], d["edi"], tmp_path / "sfm", cfg=SfmConfig(mode="given"))
    assert rep["registration"]["images"] == 5 * 3 + 1
    poses = read_poses(tmp_path / "sfm")
    assert poses.sharp[3] and poses.registered[3].all()
    np.testing.assert_allclose(poses.c2w[3, 1], poses.c2w[3, 0])
    assert len(read_test_cameras(tmp_path / "sfm")) == 6  # blur-view sharp images only
