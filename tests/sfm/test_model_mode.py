"""An existing COLMAP model as the poses (issue 33 part 5): `eigs sfm --mode model --model DIR` on a scene with
frame names and a model written by pycolmap with known poses, binary and text."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from eigs.artifacts.edi import EdiResult, write_edi
from eigs.artifacts.poses import read_poses
from eigs.cli import main
from eigs.scene import write_scene
from eigs.scene.model import Camera, Frames, Scene

V, W, H, B = 5, 32, 24, 2
K = np.array([[30.0, 0, 16.0], [0, 30.0, 12.0], [0, 0, 1.0]])
EXPOSURE, PERIOD = 20_000, 100_000
NAMES = [f"images/frame_{v:03d}.png" for v in range(V)]
SHARP_VIEW = 3


def _c2w_truth(rng: np.random.Generator) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    c2w = np.tile(np.eye(4), (V, 1, 1))
    c2w[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, 0.3, (V, 3))).as_matrix()
    c2w[:, :3, 3] = np.stack([np.linspace(-2, 2, V), rng.normal(0, 0.3, V), rng.normal(5, 0.3, V)], 1)
    return c2w


@pytest.fixture
def setup(tmp_path):
    return build_case(tmp_path)


def build_case(tmp_path: Path) -> dict:
    """scene.h5 with frame names, edi.h5, and the COLMAP model (binary in model/, text in model_txt/) under
    ``tmp_path``; returns the directory, the true poses, latent times, exposure starts and the model's points."""
    import pycolmap

    rng = np.random.default_rng(4)
    starts = np.arange(V, dtype=np.int64) * PERIOD
    scene = Scene(name="named", camera=Camera(K=K.copy(), width=W, height=H), channels=1,
                  frames=Frames(blurry=rng.integers(0, 255, (V, H, W, 1), dtype=np.uint8),
                                exposure_us=np.stack([starts, starts + EXPOSURE], 1), names=NAMES))  # fmt: skip
    write_scene(scene, tmp_path / "scene.h5")
    ts = starts[:, None] + np.arange(B + 1)[None, :] * (EXPOSURE // B)  # latent k = 1 is the exposure midpoint
    sharp = np.zeros(V, bool)
    sharp[SHARP_VIEW] = True
    write_edi(EdiResult(latent=np.zeros((V, B + 1, H, W, 1), np.float32), timestamps_us=ts,
                        cum_counts=np.zeros((V, B + 1, H, W), np.int32), threshold=np.full(V, 0.2), sharp=sharp,
                        event_count=np.zeros(V, np.int64), events_per_pixel=np.zeros(V), blur_extent_px=np.zeros(V),
                        mode="estimated", threshold_scope="scene", scene_name="named"),
              tmp_path / "edi.h5")  # fmt: skip
    c2w = _c2w_truth(rng)
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=W, height=H, params=[30, 30, 16, 12],
                                                    camera_id=1))  # fmt: skip
    order = [2, 0, 4, 1, 3]  # image ids unrelated to the view order; names without the folder
    for v in order:
        w2c = np.linalg.inv(c2w[v])
        img = pycolmap.Image(name=f"frame_{v:03d}.png", camera_id=1, image_id=10 + v)
        rec.add_image_with_trivial_frame(img, pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3]))
    extra = pycolmap.Image(name="frame_999.png", camera_id=1, image_id=99)
    rec.add_image_with_trivial_frame(extra, pycolmap.Rigid3d())
    points = rng.normal(0, 1, (50, 3)) + np.array([0, 0, 12.0])
    for p in points:
        rec.add_point3D(p, pycolmap.Track(), np.array([200, 100, 50], np.uint8))
    (tmp_path / "model").mkdir()
    rec.write(str(tmp_path / "model"))
    (tmp_path / "model_txt").mkdir()
    rec.write_text(str(tmp_path / "model_txt"))
    return {"dir": tmp_path, "c2w": c2w, "ts": ts, "starts": starts, "points": points}


def _sfm(d: Path, model: Path, *extra: str) -> int:
    return main(["sfm", str(d / "scene.h5"), str(d / "edi.h5"), "-o", str(d / "sfm"), "--mode", "model", "--model",
                 str(model), "--no-plot", *extra])  # fmt: skip


@pytest.mark.parametrize("layout", ["model", "model_txt"])
def test_model_poses_reach_the_artifact_unchanged(setup, layout):
    """The latent at each exposure midpoint carries the model's pose exactly (c2w = inverse(cam_from_world), then
    the recorded canonical similarity); the other latents are interpolated in time through the neighbouring frames'
    poses (checked against scipy's slerp); a sharp view copies its pose; the model's points reach init."""
    from scipy.spatial.transform import Rotation, Slerp

    d = setup["dir"]
    assert _sfm(d, d / layout) == 0
    poses = read_poses(d / "sfm")
    assert poses.mode == "model" and poses.registered.all()
    back = np.linalg.inv(poses.canonical)  # canonical → model frame (a similarity: scale on the translation)
    s = np.cbrt(np.linalg.det(poses.canonical[:3, :3]))

    def to_model(c):
        out = back @ c
        out[:3, :3] = out[:3, :3] * s  # undo the scale the similarity applied to the rotation columns
        return out

    c2w = setup["c2w"]
    for v in range(V):
        np.testing.assert_allclose(to_model(poses.c2w[v, 1]), c2w[v], atol=1e-9)
    mids = setup["starts"] + EXPOSURE // 2
    rot = Slerp(mids, Rotation.from_matrix(c2w[:, :3, :3]))
    for v in range(V):
        for k in (0, 2):
            t = float(np.clip(setup["ts"][v, k], mids[0], mids[-1]))
            want_R = c2w[SHARP_VIEW, :3, :3] if v == SHARP_VIEW else rot(t).as_matrix()
            want_c = c2w[SHARP_VIEW, :3, 3] if v == SHARP_VIEW else np.array(
                [np.interp(t, mids, c2w[:, i, 3]) for i in range(3)])  # fmt: skip
            got = to_model(poses.c2w[v, k])
            np.testing.assert_allclose(got[:3, :3], want_R, atol=1e-9)
            np.testing.assert_allclose(got[:3, 3], want_c, atol=1e-9)
    import json

    rep = json.loads((d / "sfm" / "report.json").read_text())
    assert rep["mode"] == "model" and rep["model"]["unmatched_images"] == ["frame_999.png"]
    assert rep["model"]["points_from"] == "the model"
    assert main(["init", str(d / "sfm"), "-o", str(d / "init.ply"), "--config", '{"min_points": 10}']) == 0
    from eigs.artifacts.gaussians import read_gaussian_ply

    cloud = read_gaussian_ply(d / "init.ply")
    assert cloud.means.shape[0] == len(setup["points"])
    canon = poses.canonical
    want = (canon[:3, :3] @ setup["points"].T).T + canon[:3, 3]
    np.testing.assert_allclose(np.sort(cloud.means[:, 0]), np.sort(want[:, 0]), atol=1e-5)


def test_model_at_twice_the_resolution_is_accepted(setup, tmp_path):
    import pycolmap

    d = setup["dir"]
    rec = pycolmap.Reconstruction(str(d / "model"))
    rec.cameras[1].width, rec.cameras[1].height = 2 * W, 2 * H
    rec.cameras[1].params = [60.0, 60.0, 32.0, 24.0]
    big = tmp_path / "big"
    big.mkdir()
    rec.write(str(big))
    assert _sfm(d, big) == 0


def _expect_error(capsys, d: Path, model: Path, *extra: str) -> str:
    code = _sfm(d, model, *extra)
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    assert not (d / "sfm").exists()
    assert not [p for p in os.listdir(d) if p.startswith(".sfm.")]
    return err


def test_model_errors_name_the_file_and_the_problem(setup, tmp_path, capsys):
    import pycolmap

    d = setup["dir"]
    err = _expect_error(capsys, d, tmp_path / "nope")
    assert f"{tmp_path / 'nope'}: no such COLMAP model directory" in err
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "unreadable COLMAP model" in _expect_error(capsys, d, empty)
    broken = tmp_path / "broken"
    shutil.copytree(d / "model", broken)
    data = (broken / "frames.bin").read_bytes()
    (broken / "frames.bin").write_bytes(data[: len(data) // 2])
    assert f"{broken}: unreadable COLMAP model" in _expect_error(capsys, d, broken)
    # a model missing the image of view 2
    rec = pycolmap.Reconstruction(str(d / "model"))
    rec.deregister_frame(rec.images[12].frame_id)
    missing = tmp_path / "missing"
    missing.mkdir()
    rec.write(str(missing))
    err = _expect_error(capsys, d, missing)
    assert f"{missing}: the model's image frame_002.png (view 2) has no pose" in err or \
        f"{missing}: the model has no image for view 2 (images/frame_002.png)" in err  # fmt: skip
    # intrinsics that disagree beyond the tolerance
    rec = pycolmap.Reconstruction(str(d / "model"))
    rec.cameras[1].params = [33.0, 33.0, 16.0, 12.0]
    wrong = tmp_path / "wrong"
    wrong.mkdir()
    rec.write(str(wrong))
    err = _expect_error(capsys, d, wrong)
    assert f"{wrong}: camera 1 has fx, fy, cx, cy = 33, 33, 16, 12 but the scene 30, 30, 16, 12" in err
    assert _sfm(d, wrong, "--intrinsics-tolerance", "0.2") == 0
