"""``eigs view`` without a browser: the splat and camera conversions, run discovery, the one-line errors, and a
server that starts, serves its (bundled, offline) web client and stops. The browser test is test_view_browser.py;
:func:`make_view_case` builds the scene both use."""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from eigs.artifacts.gaussians import GaussianCloud, read_gaussian_ply, rgb_to_sh_dc, write_gaussian_ply
from eigs.artifacts.poses import METHOD_GIVEN, LatentPoses, TestCameras, write_poses, write_test_cameras
from eigs.errors import EigsError
from eigs.scene import Camera, Frames, Scene, write_scene
from eigs.view.runs import (
    cloud_to_splats,
    fov_y,
    matrix_to_quat,
    pick_camera,
    quat_to_matrix,
    resolve_run,
    scene_cameras,
    sibling_runs,
    view_camera,
)

W, H = 320, 240
K = np.array([[280.0, 0.0, W / 2], [0.0, 280.0, H / 2], [0.0, 0.0, 1.0]])
WRONG_DEG = 30.0  # test cameras 1 and 2: camera 0 turned by this much (yaw, roll)


def rot_y(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])


def rot_z(deg: float) -> np.ndarray:
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def camera(pos: tuple[float, float, float], rot: np.ndarray | None = None) -> np.ndarray:
    """Camera-to-world (OpenCV axes) at ``pos``; identity rotation looks along +z."""
    m = np.eye(4)
    m[:3, 3] = pos
    if rot is not None:
        m[:3, :3] = rot
    return m


def pattern_cloud(seed: int = 0, invert: bool = False) -> GaussianCloud:
    """A picture that tells poses apart: a plane at z = 0 of small Gaussians coloured by position (red grows to the
    right, green downwards, a blue disc off centre), and a few big opaque blobs in front of it."""
    rng = np.random.default_rng(seed)
    xs, ys = np.meshgrid(np.linspace(-1.9, 1.9, 64), np.linspace(-1.45, 1.45, 48))
    plane = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    r = (plane[:, 0] + 1.9) / 3.8
    g = (plane[:, 1] + 1.45) / 2.9
    b = (np.hypot(plane[:, 0] - 0.6, plane[:, 1] + 0.4) < 0.5).astype(float)
    rgb = np.stack([r, g, 0.15 + 0.8 * b], 1)
    blobs = np.array([[-0.9, -0.6, -0.6], [0.9, 0.7, -0.4], [-0.5, 0.8, -0.8]])
    blob_rgb = np.array([[1.0, 1.0, 1.0], [0.1, 0.9, 0.9], [0.95, 0.85, 0.1]])
    means = np.concatenate([plane, blobs])
    rgb = np.clip(np.concatenate([rgb, blob_rgb]), 0.02, 0.98)
    if invert:
        rgb = 1.0 - rgb
    n = len(means)
    scales = np.concatenate([np.full((len(plane), 3), [0.045, 0.045, 0.01]), np.full((3, 3), 0.22)])
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    quats[: len(plane)] += rng.normal(0, 0.01, (len(plane), 4))  # not all axis-aligned
    return GaussianCloud(
        means=means.astype(np.float32),
        f_dc=rgb_to_sh_dc(rgb).astype(np.float32),
        f_rest=np.zeros((n, 3, 0), np.float32),
        opacity=np.full(n, 4.0, np.float32),
        log_scales=np.log(scales).astype(np.float32),
        quats=(quats / np.linalg.norm(quats, axis=1, keepdims=True)).astype(np.float32),
    )


def make_view_case(root: Path) -> dict[str, Path]:
    """``root/scene.h5`` and the workflow layout ``root/b4/{sfm, 3dgs, eigs, field}``: two Gaussian runs (the
    pattern and its colour negative), a field run (model.npz), training cameras around the plane and three test
    cameras at (0, 0, −3): 0 looks at the plane, 1 is it yawed by 30°, 2 rolled by 30°."""
    scene = Scene(name="viewcase", camera=Camera(K=K, width=W, height=H), channels=3, camera_response="linear",
                  synthetic=True, background=np.zeros(3), source="unit test")  # fmt: skip
    v, lat = 3, 2
    scene.frames = Frames(np.zeros((v, H, W, 3), np.uint8), None)
    write_scene(scene, root / "scene.h5")
    bdir = root / "b4"
    sfm = bdir / "sfm"
    sfm.mkdir(parents=True)
    views = np.stack([np.stack([camera((0.4 * i - 0.4 + 0.02 * k, 0.1 * i, -3.2), rot_y(-7.0 * (i - 1)))
                                for k in range(lat)]) for i in range(v)])  # fmt: skip
    poses = LatentPoses(c2w=views, timestamps_us=np.tile(np.arange(lat, dtype=np.int64) * 100, (v, 1)),
                        registered=np.ones((v, lat), bool), interpolated=np.zeros((v, lat), bool),
                        sharp=np.zeros(v, bool), K=K, width=W, height=H, mode="given")  # fmt: skip
    write_poses(poses, sfm / "poses.h5")
    tc2w = np.stack([camera((0, 0, -3)), camera((0, 0, -3), rot_y(WRONG_DEG)), camera((0, 0, -3), rot_z(WRONG_DEG))])
    s = len(tc2w)
    write_test_cameras(TestCameras(c2w=tc2w, K=np.repeat(K[None], s, 0), width=W, height=H,
                                   index=np.arange(s, dtype=np.int64), kind=np.ones(s, np.uint8),
                                   view=np.full(s, -1, np.int64), t_us=np.arange(s, dtype=np.int64),
                                   method=np.full(s, METHOD_GIVEN, np.uint8), reprojection_error_px=np.zeros(s),
                                   num_inliers=np.zeros(s, np.int64)), sfm / "test_cameras.h5")  # fmt: skip
    out = {"scene": root / "scene.h5", "sfm": sfm}
    for name, invert in (("3dgs", False), ("eigs", True)):
        run = bdir / name
        run.mkdir()
        write_gaussian_ply(pattern_cloud(invert=invert), run / "model.ply")
        cfg = {"train": {"method": name, "steps": 10, "sh_degree": 0},
               "inputs": {"scene": str(root / "scene.h5"), "sfm": str(sfm)}}  # fmt: skip
        (run / "config.json").write_text(json.dumps(cfg))
        out[name] = run
    field = bdir / "field"
    field.mkdir()
    np.savez(field / "model.npz", density=np.zeros(1))
    (field / "config.json").write_text(json.dumps({"train": {"method": "field"}, "inputs": {"sfm": str(sfm)}}))
    out["field"] = field
    return out


# ---- conversions ---------------------------------------------------------------------------------------------


def test_covariance_colour_and_opacity_follow_the_ply_conventions():
    rng = np.random.default_rng(1)
    n = 50
    q = rng.normal(size=(n, 4))
    cloud = GaussianCloud(means=rng.normal(size=(n, 3)).astype(np.float32),
                          f_dc=rgb_to_sh_dc(rng.uniform(-0.2, 1.2, (n, 3))).astype(np.float32),
                          f_rest=np.zeros((n, 3, 3), np.float32), opacity=rng.normal(size=n).astype(np.float32),
                          log_scales=rng.normal(-2, 0.5, (n, 3)).astype(np.float32),
                          quats=(q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32))  # fmt: skip
    s = cloud_to_splats(cloud)
    assert s.centers.shape == (n, 3) and s.covariances.shape == (n, 3, 3)
    assert s.rgbs.shape == (n, 3) and s.opacities.shape == (n, 1)
    rot = quat_to_matrix(cloud.quats)
    assert np.allclose(rot @ np.transpose(rot, (0, 2, 1)), np.eye(3), atol=1e-5)
    assert np.allclose(np.linalg.det(rot), 1.0, atol=1e-5)
    # the covariance's eigenvalues are the variances, its eigenvectors the rotation's columns
    for i in range(5):
        ev = np.sort(np.linalg.eigvalsh(s.covariances[i].astype(np.float64)))
        assert np.allclose(ev, np.sort(np.exp(2 * cloud.log_scales[i])), rtol=1e-4)
        axis0 = rot[i][:, 0]
        assert np.allclose(s.covariances[i] @ axis0, np.exp(2 * cloud.log_scales[i, 0]) * axis0, rtol=1e-3, atol=1e-7)
    assert np.all((s.rgbs >= 0) & (s.rgbs <= 1))
    inside = np.all((cloud.f_dc * 0.28209479 + 0.5 > 0) & (cloud.f_dc * 0.28209479 + 0.5 < 1), axis=1)
    assert np.allclose(s.rgbs[inside], cloud.f_dc[inside] * 0.28209479 + 0.5, atol=1e-6)
    assert np.allclose(s.opacities[:, 0], 1 / (1 + np.exp(-cloud.opacity)), atol=1e-6)


def test_quaternion_round_trip_and_wxyz_convention():
    q = np.array([0.9, 0.1, -0.3, 0.2])
    q /= np.linalg.norm(q)
    assert np.allclose(matrix_to_quat(quat_to_matrix(q[None])[0]), q)
    # 90° about z: x → y
    r = quat_to_matrix(np.array([[np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)]]))[0]
    assert np.allclose(r @ [1, 0, 0], [0, 1, 0], atol=1e-12)


def test_view_camera_keeps_the_opencv_pose_and_fov():
    c2w = camera((1.0, 2.0, -3.0), rot_y(20.0))
    cam = view_camera("c", c2w, K, W, H, centre=np.zeros(3))
    assert np.allclose(cam.position, [1, 2, -3])
    assert np.allclose(quat_to_matrix(cam.wxyz[None])[0], c2w[:3, :3])
    assert np.allclose(cam.up, -c2w[:3, 1])
    assert cam.fov_y == pytest.approx(2 * np.arctan(H / 2 / 280.0))
    assert fov_y(K, H) == cam.fov_y and cam.aspect == pytest.approx(W / H)
    # the orbit centre lies on the optical axis, in front
    d = cam.look_at - cam.position
    assert np.allclose(np.cross(d, c2w[:3, 2]), 0, atol=1e-9) and np.dot(d, c2w[:3, 2]) > 0


# ---- runs, cameras, errors -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def case(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_view_case(tmp_path_factory.mktemp("view"))


def test_runs_resolve_and_siblings_share_the_sfm_folder(case):
    run = resolve_run(case["3dgs"])
    assert run.kind == "gaussians" and run.label == "b4/3dgs"
    assert run.sfm == case["sfm"] and run.scene == case["scene"]
    assert [p.name for p in sibling_runs(run)] == ["eigs", "field"]
    assert resolve_run(case["field"]).kind == "field"
    train, test, size = scene_cameras(run.sfm, np.zeros(3))
    assert size == (W, H) and len(train) == 3 and len(test) == 3
    assert pick_camera("test:1", train, test) is test[1] and pick_camera("train:2", train, test) is train[2]
    for bad in ("test:9", "side:0", "test:x"):
        with pytest.raises(EigsError, match="--camera"):
            pick_camera(bad, train, test)
    assert np.allclose(read_gaussian_ply(run.model).means, cloud_to_splats(read_gaussian_ply(run.model)).centers)


def _eigs(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "eigs", *args], capture_output=True, text=True, timeout=timeout)


@pytest.mark.parametrize(
    "which, message",
    [
        ("missing", "no such run folder"),
        ("empty", "no config.json"),
        ("field", "a field run (model.npz) has no Gaussians to show"),
    ],
)
def test_view_errors_are_one_line(case, tmp_path, which, message):
    path = {"missing": tmp_path / "nope", "empty": tmp_path, "field": case["field"]}[which]
    res = _eigs("view", str(path), "--port", "0", timeout=60)
    assert res.returncode == 2, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("eigs view: error: ") and message in lines[0], res.stderr


class ViewerProcess:
    """``eigs view ARGS --port 0`` in its own process group; ``url`` is the address it printed. Its output is read
    by threads (a full pipe never blocks it); :meth:`stop` sends SIGTERM and waits."""

    def __init__(self, *args: str, timeout: float = 90) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "eigs", "view", *args, "--port", "0"],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                     start_new_session=True)  # fmt: skip
        self.stdout: queue.Queue[str] = queue.Queue()
        self.stderr: list[str] = []
        threading.Thread(target=self._pump, args=(self.proc.stdout, self.stdout.put), daemon=True).start()
        threading.Thread(target=self._pump, args=(self.proc.stderr, self.stderr.append), daemon=True).start()
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.proc.poll() is None:
            try:
                line = self.stdout.get(timeout=0.5)
            except queue.Empty:
                continue
            if " at http://" in line:
                self.url = line.split(" at ", 1)[1].split()[0]
                return
        self.stop()
        raise AssertionError(f"eigs view printed no URL; stderr: {''.join(self.stderr)}")

    @staticmethod
    def _pump(stream: Any, sink: Any) -> None:
        for line in stream:
            sink(line)

    def stop(self, timeout: float = 20) -> int:
        """SIGTERM and wait; SIGKILL the process group when it does not stop (then fail)."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
                raise AssertionError("eigs view did not stop on SIGTERM") from None
        return self.proc.returncode


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_viewer_serves_its_bundled_client_and_stops_on_a_signal(case, sig):
    viewer = ViewerProcess(str(case["3dgs"]))
    try:
        assert viewer.url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(viewer.url, timeout=20) as resp:
            page = resp.read().decode("utf-8", "replace")
        assert resp.status == 200 and '<div id="root">' in page
        viewer.proc.send_signal(sig)
        viewer.proc.wait(20)
    finally:
        code = viewer.stop()
    assert code == 0, "".join(viewer.stderr)
    log = "".join(viewer.stderr)
    assert "b4/3dgs: 3075 Gaussians" in log and "b4/eigs: 3075 Gaussians" in log  # the sibling run, not the field
    assert "field: a field run (model.npz), not shown" in log and "viewer stopped" in log
