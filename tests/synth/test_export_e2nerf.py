"""E²NeRF synthetic layout export: files, JSON structure as E²NeRF's loader reads it, events.pt bins."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from eigs.scene import read_scene, write_scene
from eigs.synth.export_e2nerf import opencv_to_blender, write_e2nerf_synthetic
from eigs.synth.generate import generate
from tests.synth.test_generate import SMALL


@pytest.fixture(scope="module")
def gen():
    return generate("toy", {**SMALL, "n_train": 3, "n_novel": 2}, show_progress=False)


def load_like_e2nerf(root):
    """What E²NeRF's load_blender.py reads (frames[0:200:2] → train/r_{2i}.png + matrices 1, 5, 9, 13, 17;
    test frames[0:200] → test/r_{j}.png + matrix 1)."""
    train = json.loads((root / "transform_train.json").read_text())
    test = json.loads((root / "transform_test.json").read_text())
    imgs, poses = [], []
    for num, frame in zip(range(0, 400, 2), train["frames"][0:200:2], strict=False):
        imgs.append(cv2.imread(str(root / f"train/r_{num}.png"), cv2.IMREAD_UNCHANGED))
        poses.append(np.array([frame["transform_matrix"][i] for i in (1, 5, 9, 13, 17)]))
    test_imgs = [cv2.imread(str(root / f"test/r_{j}.png"), cv2.IMREAD_UNCHANGED)
                 for j in range(len(test["frames"][0:200]))]
    test_poses = [np.array(f["transform_matrix"][1]) for f in test["frames"][0:200]]
    return train, test, imgs, np.array(poses), test_imgs, np.array(test_poses)


def check_layout(root, scene, path_fn=None):
    train, test, imgs, poses, test_imgs, test_poses = load_like_e2nerf(root)
    v = scene.n_views
    h, w = scene.camera.height, scene.camera.width
    assert len(train["frames"]) == 2 * v and len(imgs) == v
    for i, img in enumerate(imgs):
        assert img.shape == (h, w, 4) and np.all(img[..., 3] == 255)
        assert np.array_equal(img[..., 2::-1], scene.frames.blurry[i])  # BGRA on disk → RGB
    focal = 0.5 * w / np.tan(0.5 * train["camera_angle_x"])
    assert focal == pytest.approx(scene.camera.K[0, 0], rel=1e-9)
    assert np.allclose(poses, opencv_to_blender(scene.poses.latent_c2w))
    assert all(len(f["transform_matrix"]) == 18 for f in train["frames"])
    # test: blur view k at even slots (GT at the first latent pose), novel view k at odd slots
    sh = scene.sharp
    novel = np.flatnonzero(sh.kind == 1)
    pairs = min(v, novel.size)
    assert len(test_imgs) == 2 * pairs
    for k in range(pairs):
        assert np.array_equal(test_imgs[2 * k][..., 2::-1], sh.images[(sh.kind == 0) & (sh.view == k)][0])
        assert np.array_equal(test_imgs[2 * k + 1][..., 2::-1], sh.images[novel[k]])
        assert np.allclose(test_poses[2 * k], opencv_to_blender(scene.poses.latent_c2w[k, 0]))
        assert np.allclose(test_poses[2 * k + 1], opencv_to_blender(sh.c2w[novel[k]]))
    # matrix times: entry j at start + (j − 1)·exposure/16
    start = scene.frames.exposure_us[:, 0]
    t = np.array([f["eigs_time_us"] for f in train["frames"][0::2]])
    T = scene.frames.exposure_us[:, 1] - start
    assert np.allclose(t, start[:, None] + (np.arange(18)[None] - 1) * T[:, None] / 16)
    if path_fn is not None:
        m = np.array([f["transform_matrix"] for f in train["frames"][0::2]])
        assert np.allclose(m, opencv_to_blender(path_fn(t.ravel()).reshape(v, 18, 4, 4)), atol=1e-9)
    return train


def check_events(root, scene, pre_us=None):
    counts = torch.load(root / "events.pt")
    v = scene.n_views
    h, w = scene.camera.height, scene.camera.width
    assert counts.dtype == torch.float64 and tuple(counts.shape) == (v, 4, h * w)
    c = counts.numpy().reshape(v, 4, h, w)
    ev = scene.events
    for i in range(v):
        edges = scene.poses.latent_t_us[i].copy()
        if pre_us is not None:
            edges[0] -= pre_us
        for k in range(4):
            m = (ev.t >= edges[k]) & (ev.t < edges[k + 1])
            ref = np.zeros((h, w))
            np.add.at(ref, (ev.y[m], ev.x[m]), ev.p[m].astype(float))
            assert np.array_equal(c[i, k], ref), (i, k)
        if pre_us is None:  # the 4 bins together are exactly the view's exposure events
            a, b = ev.view_index[i]
            net = np.zeros((h, w))
            np.add.at(net, (ev.y[a:b], ev.x[a:b]), ev.p[a:b].astype(float))
            assert np.array_equal(c[i].sum(axis=0), net)
    return c


def test_export_from_generated(gen, tmp_path):
    root = tmp_path / "toy_e2nerf"
    info = write_e2nerf_synthetic(gen, root)
    train = check_layout(root, gen.scene, gen.path)
    c = check_events(root, gen.scene)
    assert np.abs(c).sum() > 0
    assert np.array_equal(info["bin_edges_us"], gen.scene.poses.latent_t_us)
    assert train["eigs"]["bin_edges_us"] == gen.scene.poses.latent_t_us.tolist()
    kinds = [f["eigs_kind"] for f in train["frames"]]
    assert kinds == ["train", "novel", "train", "novel", "train", "filler"]


def test_export_from_scene_file_matches(gen, tmp_path):
    write_scene(gen.scene, tmp_path / "scene.h5")
    scene = read_scene(tmp_path / "scene.h5")
    write_e2nerf_synthetic(scene, tmp_path / "a")
    write_e2nerf_synthetic(gen, tmp_path / "b")
    ta = json.loads((tmp_path / "a/transform_train.json").read_text())
    tb = json.loads((tmp_path / "b/transform_train.json").read_text())
    ma = np.array([f["transform_matrix"] for f in ta["frames"][0::2]])
    mb = np.array([f["transform_matrix"] for f in tb["frames"][0::2]])
    assert np.allclose(ma[:, 1:], mb[:, 1:], atol=1e-9)  # sub-frame times: exact trajectory samples
    # entry 0 lies before the exposure (lead or gap, where the orbit moves fast in this small config): interpolated
    assert np.allclose(ma[:, 0], mb[:, 0], atol=0.1)
    assert torch.equal(torch.load(tmp_path / "a/events.pt"), torch.load(tmp_path / "b/events.pt"))
    check_layout(tmp_path / "a", scene)


def test_export_pre_latent_bin(gen, tmp_path):
    info = write_e2nerf_synthetic(gen, tmp_path / "pre", include_pre_latent=True)
    pre = int(gen.params["exposure_us"] // 16)
    check_events(tmp_path / "pre", gen.scene, pre_us=pre)
    assert np.array_equal(info["bin_edges_us"][:, 0], gen.scene.poses.latent_t_us[:, 0] - pre)


def test_cli_writes_layout(tmp_path):
    from eigs.cli import main

    ov = json.dumps({**SMALL, "n_train": 2, "n_novel": 2})
    code = main(["synth", "--scene", "toy", "--overrides", ov, "-o", str(tmp_path / "s.h5"),
                 "--e2nerf-layout", str(tmp_path / "e2")])
    assert code == 0
    check_layout(tmp_path / "e2", read_scene(tmp_path / "s.h5"))
