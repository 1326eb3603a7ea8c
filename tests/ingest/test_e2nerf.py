"""E²NeRF synthetic and real layouts: exact round trips, projection of a known point, bad inputs."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import H, W, write_e2nerf_real, write_e2nerf_synthetic

FLIP_YZ = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL camera axes → OpenCV camera axes (right-multiplied)


@pytest.fixture()
def synthetic(tmp_path):
    return write_e2nerf_synthetic(tmp_path / "chair")


@pytest.fixture()
def real(tmp_path):
    return write_e2nerf_real(tmp_path / "letter")


def test_synthetic_round_trip(synthetic, tmp_path, capsys):
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-synthetic", synthetic.folder, out) == 0
    printed = capsys.readouterr().out
    assert "views: 3 blurry frames" in printed and "sharp images (3 blur-view, 3 novel-view)" in printed
    s = read_scene(out)
    assert s.name == "chair" and s.synthetic and s.channels == 3
    np.testing.assert_array_equal(s.frames.blurry, synthetic.train_rgb)
    np.testing.assert_array_equal(s.frames.exposure_us, np.tile([0, 170_000], (3, 1)))
    # latent poses: transform_matrix entries 1, 5, 9, 13, 17, camera y and z axes negated
    want = synthetic.train_mats[:, [1, 5, 9, 13, 17]] @ FLIP_YZ
    assert np.abs(s.poses.latent_c2w - want).max() <= 1e-12
    assert s.poses.source == "ground-truth"
    np.testing.assert_array_equal(s.poses.latent_t_us, np.tile([10_000, 50_000, 90_000, 130_000, 170_000], (3, 1)))
    np.testing.assert_array_equal(s.binned.counts, synthetic.counts)
    np.testing.assert_array_equal(s.binned.bin_edges_us, np.tile([0, 50_000, 90_000, 130_000, 170_000], (3, 1)))
    # sharp ground truth: RGBA composited on black, kind 0 for even r_k (view k/2), 1 for odd (view −1)
    rgba = synthetic.test_rgba.astype(np.float64)
    want_img = np.floor(rgba[..., :3] * rgba[..., 3:] / 255.0 + 0.5).astype(np.uint8)
    np.testing.assert_array_equal(s.sharp.images, want_img)
    np.testing.assert_array_equal(s.sharp.kind, [0, 1, 0, 1, 0, 1])
    np.testing.assert_array_equal(s.sharp.view, [0, -1, 1, -1, 2, -1])
    np.testing.assert_array_equal(s.sharp.t_us, [10_000, -1, 10_000, -1, 10_000, -1])  # novel views: no view clock
    assert np.abs(s.sharp.c2w - synthetic.test_mats[:, 1] @ FLIP_YZ).max() <= 1e-12
    np.testing.assert_array_equal(s.background, [0, 0, 0])


def test_synthetic_known_point_projects_like_blender(synthetic, tmp_path):
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-synthetic", synthetic.folder, out) == 0
    s = read_scene(out)
    f = 0.5 * W / np.tan(0.5 * synthetic.angle_x)
    blender = synthetic.train_mats[1, 5]  # view 1, latent pose 1 (entry 5)
    # a point 4 units in front of the Blender camera (looking down −z), off-centre
    p_cam_gl = np.array([0.7, -0.4, -4.0, 1.0])
    p_world = blender @ p_cam_gl
    # Blender image plane: x right, y up; pixel (j, i) covers [j, j+1) × [i, i+1), centre of the image at (W/2, H/2)
    u_blender = W / 2 + f * p_cam_gl[0] / -p_cam_gl[2]
    v_blender = H / 2 - f * p_cam_gl[1] / -p_cam_gl[2]
    p_cam = np.linalg.inv(s.poses.latent_c2w[1, 1]) @ p_world
    uvw = s.camera.K @ p_cam[:3]
    assert np.allclose(uvw[:2] / uvw[2], [u_blender, v_blender], atol=1e-9)


def test_synthetic_views_selection(synthetic, tmp_path):
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-synthetic", synthetic.folder, out, "--views", "1:3") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.blurry, synthetic.train_rgb[1:3])
    np.testing.assert_array_equal(s.binned.counts, synthetic.counts[1:3])
    np.testing.assert_array_equal(s.sharp.view, [-1, 0, -1, 1, -1])  # blur-view GT of view 0 dropped


def test_real_round_trip(real, tmp_path, capsys):
    import cv2

    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-real", real.folder, out) == 0
    assert "poses: 5 latent per view (estimated)" in capsys.readouterr().out
    s = read_scene(out)
    assert not s.synthetic and s.channels == 3 and s.sharp is None
    jpg = np.stack([cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB) for p in real.images])
    np.testing.assert_array_equal(s.frames.blurry, jpg)
    # LLFF [down, right, back] → NeRF [right, up, back] (load_llff.py) → OpenCV (negate y, z)
    assert np.abs(s.poses.latent_c2w - real.c2w_cv).max() <= 1e-12
    np.testing.assert_array_equal(s.poses.latent_t_us, np.tile(25_001 * np.arange(5), (2, 1)))
    np.testing.assert_array_equal(s.frames.exposure_us, np.tile([0, 100_004], (2, 1)))
    np.testing.assert_array_equal(s.binned.bin_edges_us, np.tile([0, 25_001, 50_002, 75_003, 100_004], (2, 1)))
    np.testing.assert_array_equal(s.binned.counts, real.counts)
    np.testing.assert_allclose(s.camera.K, [[real.focal, 0, W / 2], [0, real.focal, H / 2], [0, 0, 1]])


def test_real_llff_axes_via_nerf_convention(real, tmp_path):
    """Independent path: load_llff.py's [right, up, back] = [col1, −col0, col2], then OpenGL → OpenCV."""
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-real", real.folder, out) == 0
    s = read_scene(out)
    rows = np.load(real.folder / "poses_bounds.npy")[:, :15].reshape(-1, 3, 5)
    nerf = np.concatenate([rows[:, :, 1:2], -rows[:, :, 0:1], rows[:, :, 2:3], rows[:, :, 3:4]], axis=2)
    c2w_gl = np.zeros((rows.shape[0], 4, 4))
    c2w_gl[:, :3] = nerf
    c2w_gl[:, 3, 3] = 1
    assert np.abs(s.poses.latent_c2w.reshape(-1, 4, 4) - c2w_gl @ FLIP_YZ).max() <= 1e-12


def test_real_known_point_projects_like_colmap(real, tmp_path):
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-real", real.folder, out) == 0
    s = read_scene(out)
    row = np.load(real.folder / "poses_bounds.npy")[7, :15].reshape(3, 5)
    r, t = row[:, :3], row[:, 3]
    p_llff = np.array([0.3, -0.2, -5.0])  # (down, right, back): in front of the camera, which looks along −back
    p_world = r @ p_llff + t
    # COLMAP/LLFF pinhole: pixel centres at +0.5, principal point (W/2, H/2), row from "down", column from "right"
    u = W / 2 + real.focal * p_llff[1] / -p_llff[2]
    v = H / 2 + real.focal * p_llff[0] / -p_llff[2]
    p_cam = np.linalg.inv(s.poses.latent_c2w[1, 2]) @ np.append(p_world, 1.0)
    uvw = s.camera.K @ p_cam[:3]
    assert np.allclose(uvw[:2] / uvw[2], [u, v], atol=1e-9)


def test_real_accepts_event_pt(tmp_path):
    fx = write_e2nerf_real(tmp_path / "toys", event_name="event.pt")
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-real", fx.folder, out) == 0
    np.testing.assert_array_equal(read_scene(out).binned.counts, fx.counts)


def test_intrinsics_override(real, tmp_path):
    out = tmp_path / "scene.h5"
    assert run_ingest("e2nerf-real", real.folder, out, "--intrinsics", "10,11,5,3") == 0
    np.testing.assert_array_equal(read_scene(out).camera.K, [[10, 0, 5.5], [0, 11, 3.5], [0, 0, 1]])


# --- bad inputs ---------------------------------------------------------------------------------------------------
def _save_events(path, a):
    import torch

    torch.save(torch.from_numpy(a), path)


def test_missing_folder(tmp_path, capsys):
    err = expect_failure(capsys, "e2nerf-synthetic", tmp_path / "nope", tmp_path / "s.h5")
    assert "nope: no such folder" in err


def test_missing_events(synthetic, tmp_path, capsys):
    (synthetic.folder / "events.pt").unlink()
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "events.pt: missing event tensor" in err


def test_truncated_events(synthetic, tmp_path, capsys):
    p = synthetic.folder / "events.pt"
    p.write_bytes(p.read_bytes()[:300])
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "events.pt: not a readable torch tensor file, truncated or corrupted" in err


def test_events_wrong_shape(synthetic, tmp_path, capsys):
    _save_events(synthetic.folder / "events.pt", np.zeros((3, 4, H * W + 1)))
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert f"events.pt: has shape 3×4×{H * W + 1}, expected 3×4×{H * W}" in err


def test_events_view_count_disagrees_with_images(synthetic, tmp_path, capsys):
    _save_events(synthetic.folder / "events.pt", np.zeros((4, 4, H * W)))
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "events.pt: has shape 4×4×77, expected 3×4×77 (views × bins × H·W for 3 images" in err


def test_events_not_integral(synthetic, tmp_path, capsys):
    a = np.zeros((3, 4, H * W))
    a[2, 1, 3 * W + 4] = 0.5
    _save_events(synthetic.folder / "events.pt", a)
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "count 0.5 at view 2, bin 1, pixel (x=4, y=3) is not an integer" in err


def test_events_nan(synthetic, tmp_path, capsys):
    a = np.zeros((3, 4, H * W))
    a[1, 0, 0] = np.nan
    _save_events(synthetic.folder / "events.pt", a)
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "events.pt: view 1 has NaN/Inf counts" in err


def test_truncated_png(synthetic, tmp_path, capsys):
    p = synthetic.folder / "train" / "r_2.png"
    p.write_bytes(p.read_bytes()[:-30])
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "r_2.png: not a readable image, truncated or corrupted" in err


def test_gap_in_train_images(synthetic, tmp_path, capsys):
    (synthetic.folder / "train" / "r_2.png").unlink()
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "train/r_2.png: missing: E²NeRF's loader opens it for frame 2 of transform_train.json" in err


def _rewrite_file_paths(folder, how):
    """Set every frame's file_path in both JSON files: ``how(k, split)`` → new value, or None to delete it."""
    for split in ("train", "test"):
        p = folder / f"transform_{split}.json"
        meta = json.loads(p.read_text())
        for k, fr in enumerate(meta["frames"]):
            value = how(k, split)
            if value is None:
                fr.pop("file_path")
            else:
                fr["file_path"] = value
        p.write_text(json.dumps(meta))


def test_synthetic_file_path_is_informational(synthetic, tmp_path, caplog):
    """As load_blender.py: frames[0:200:2] ↔ train/r_{2i}.png and frames[0:200] ↔ test/r_i.png by counting. Layouts
    whose file_path entries are consistent, absent or arbitrary ingest to byte-identical scene files; arbitrary
    entries are reported."""
    outs = {}
    for case, how in (
        ("consistent", lambda k, split: f"./{split}/r_{k}"),
        ("absent", lambda k, split: None),
        ("arbitrary", lambda k, split: f"./somewhere/img_{(7 * k + 3) % 11}.png"),
        ("empty", lambda k, split: ""),
    ):
        _rewrite_file_paths(synthetic.folder, how)
        caplog.clear()
        outs[case] = tmp_path / f"{case}.h5"
        assert run_ingest("e2nerf-synthetic", synthetic.folder, outs[case]) == 0
        warned = [r for r in caplog.records if "file_path" in r.getMessage() and r.levelname == "WARNING"]
        assert bool(warned) == (case == "arbitrary"), case
    data = {case: p.read_bytes() for case, p in outs.items()}
    assert data["absent"] == data["consistent"] == data["arbitrary"] == data["empty"]
    s = read_scene(outs["arbitrary"])  # and it is the layout's content, counted
    np.testing.assert_array_equal(s.frames.blurry, synthetic.train_rgb)
    assert np.abs(s.poses.latent_c2w - synthetic.train_mats[:, [1, 5, 9, 13, 17]] @ FLIP_YZ).max() <= 1e-12


def test_synthetic_reads_at_most_200_frames(tmp_path):
    """frames beyond the first 200 are not read (train: 100 views from frames 0, 2, …, 198; test: 200 frames)."""
    lay = write_e2nerf_synthetic(tmp_path / "big", n_views=1)
    for split in ("train", "test"):
        p = lay.folder / f"transform_{split}.json"
        meta = json.loads(p.read_text())
        meta["frames"] = [meta["frames"][k % 2] for k in range(204)]
        p.write_text(json.dumps(meta))
    import torch

    from tests.ingest.fixtures import save_png

    rgba = np.concatenate([lay.train_rgb[0], np.full((H, W, 1), 255, np.uint8)], axis=2)
    for k in range(1, 104):  # train r_2 … r_206 (r_200 … r_206 are beyond what E²NeRF reads)
        save_png(lay.folder / "train" / f"r_{2 * k}.png", rgba)
    for k in range(2, 204):
        save_png(lay.folder / "test" / f"r_{k}.png", lay.test_rgba[k % 2])
    torch.save(torch.zeros((100, 4, H * W), dtype=torch.float64), lay.folder / "events.pt")
    out = tmp_path / "big.h5"
    assert run_ingest("e2nerf-synthetic", lay.folder, out) == 0
    s = read_scene(out)
    assert s.n_views == 100 and len(s.sharp.kind) == 200
    np.testing.assert_array_equal(s.sharp.view[:4], [0, -1, 1, -1])


def test_real_images_found_as_load_llff(tmp_path):
    """load_llff.py: sorted names ending in JPG/jpg/png (any names, no numbering), 5 poses per image."""
    lay = write_e2nerf_real(tmp_path / "toys", n_views=2)
    imgs = lay.folder / "images"
    (imgs / "000.jpg").rename(imgs / "b_first.JPG")  # sorted: "b_first.JPG" < "c_second.jpg"
    (imgs / "005.jpg").rename(imgs / "c_second.jpg")
    (imgs / "a_ignored.jpeg").write_bytes(b"not read: load_llff.py does not list .jpeg")
    (imgs / "notes.txt").write_text("not an image")
    out = tmp_path / "toys.h5"
    assert run_ingest("e2nerf-real", lay.folder, out) == 0
    s = read_scene(out)
    assert s.n_views == 2
    from PIL import Image

    np.testing.assert_array_equal(s.frames.blurry[0], np.asarray(Image.open(imgs / "b_first.JPG")))
    np.testing.assert_array_equal(s.frames.blurry[1], np.asarray(Image.open(imgs / "c_second.jpg")))
    assert np.abs(s.poses.latent_c2w - lay.c2w_cv).max() <= 1e-9  # view i ↔ rows 5i … 5i+4


def test_real_image_count_mismatch_is_an_error(real, tmp_path, capsys):
    from PIL import Image

    Image.open(real.images[0]).save(real.folder / "images" / "010.png")  # a third image, poses for two
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "poses_bounds.npy: has 10 poses but images/ has 3 images (expected 5·3 = 15)" in err


def test_too_few_matrices(synthetic, tmp_path, capsys):
    p = synthetic.folder / "transform_train.json"
    meta = json.loads(p.read_text())
    meta["frames"][2]["transform_matrix"] = meta["frames"][2]["transform_matrix"][:17]
    p.write_text(json.dumps(meta))
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "transform_train.json: frame 2: transform_matrix has shape 17×4×4, expected ≥ 18 4×4 matrices" in err


def test_nan_pose(synthetic, tmp_path, capsys):
    p = synthetic.folder / "transform_train.json"
    text = p.read_text()
    meta = json.loads(text)
    meta["frames"][0]["transform_matrix"][5][0][0] = float("nan")
    p.write_text(json.dumps(meta))
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "transform_train.json: frame 0: transform_matrix has NaN/Inf" in err


def test_corrupted_json(synthetic, tmp_path, capsys):
    p = synthetic.folder / "transform_train.json"
    p.write_text(p.read_text()[:-50])
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "transform_train.json: not valid JSON" in err


def test_plain_nerf_layout_refused(synthetic, tmp_path, capsys):
    (synthetic.folder / "transform_train.json").rename(synthetic.folder / "transforms_train.json")
    err = expect_failure(capsys, "e2nerf-synthetic", synthetic.folder, tmp_path / "s.h5")
    assert "transform_train.json: missing (found transforms_train.json" in err


def test_real_pose_count_disagrees(real, tmp_path, capsys):
    rows = np.load(real.folder / "poses_bounds.npy")
    np.save(real.folder / "poses_bounds.npy", rows[:-1])
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "poses_bounds.npy: has 9 poses but images/ has 2 images (expected 5·2 = 10)" in err


def test_real_nan_pose(real, tmp_path, capsys):
    rows = np.load(real.folder / "poses_bounds.npy")
    rows[6, 3] = np.nan
    np.save(real.folder / "poses_bounds.npy", rows)
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "poses_bounds.npy: has NaN/Inf (first in row 6)" in err


def test_real_truncated_poses(real, tmp_path, capsys):
    p = real.folder / "poses_bounds.npy"
    p.write_bytes(p.read_bytes()[:200])
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "poses_bounds.npy: not a readable .npy array, truncated or corrupted" in err


def test_real_hwf_disagrees_with_images(real, tmp_path, capsys):
    rows = np.load(real.folder / "poses_bounds.npy")
    rows[:, 9] = W + 1  # w of hwf (row-major 3×5: [1, 4])
    np.save(real.folder / "poses_bounds.npy", rows)
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert f"poses_bounds.npy: hwf says {W + 1}×{H} but the images are {W}×{H}" in err


def test_real_both_event_names(real, tmp_path, capsys):
    shutil.copy(real.folder / "events.pt", real.folder / "event.pt")
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "holds both events.pt and event.pt" in err


def test_real_truncated_jpeg(real, tmp_path, capsys):
    p = real.images[1]
    p.write_bytes(p.read_bytes()[: len(p.read_bytes()) // 2])
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5")
    assert "005.jpg: not a readable image, truncated or corrupted" in err


def test_options_that_do_not_apply(real, tmp_path, capsys):
    err = expect_failure(capsys, "e2nerf-real", real.folder, tmp_path / "s.h5", "--exposure-us", "0,10")
    assert "--exposure-us: does not apply to the e2nerf-real format" in err
