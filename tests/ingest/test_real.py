"""Real recordings in ../shared/data/real (skip locally without it; fail under CI=true): facts as documented in
its README, checked through ``eigs ingest``."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from eigs.scene import read_scene
from tests.ingest.conftest import run_ingest

DAVIS_K = "653.98456,653.98456,172.5,129.5"  # stand-in intrinsics (the recording has none)


@pytest.fixture(scope="module")
def davis(shared_real, tmp_path_factory):
    out = tmp_path_factory.mktemp("davis") / "all.h5"
    assert (
        run_ingest(
            "aedat4",
            shared_real / "davis346_lab" / "davis.aedat4",
            out,
            "--intrinsics",
            DAVIS_K,
            "--keep-events",
            "all",
        )
        == 0
    )
    return read_scene(out)


def test_davis_events(davis, shared_real):
    ev = davis.events
    assert len(ev) == 117_667
    assert int(np.count_nonzero(ev.p == 1)) == 72_363 and int(np.count_nonzero(ev.p == -1)) == 45_304
    assert (int(ev.t[0]), int(ev.t[-1])) == (1_633_953_690_975_950, 1_633_953_691_105_949)
    assert int(ev.t[-1] - ev.t[0]) == 129_999
    ref = np.load(shared_real / "davis346_lab" / "derived" / "events.npz")  # independent decode
    np.testing.assert_array_equal(ev.t, ref["t_us"].astype(np.int64))
    np.testing.assert_array_equal(ev.x, ref["x"])
    np.testing.assert_array_equal(ev.y, ref["y"])
    np.testing.assert_array_equal(ev.p, ref["p"].astype(np.int8) * 2 - 1)
    assert (davis.camera.width, davis.camera.height) == (346, 260)


def test_davis_frames(davis, shared_real):
    d = shared_real / "davis346_lab" / "derived"
    csv = np.loadtxt(d / "frames.csv", delimiter=",", skiprows=1, dtype=np.int64)
    assert davis.frames.n_views == 3 and davis.channels == 1
    np.testing.assert_array_equal(davis.frames.exposure_us, csv[:, 2:4])
    np.testing.assert_array_equal(np.diff(davis.frames.exposure_us, axis=1)[:, 0], [4773, 4773, 4773])
    np.testing.assert_array_equal((csv[:, 2] + csv[:, 3]) // 2, csv[:, 1])  # timestamp = exposure midpoint
    for i in range(3):
        png = np.asarray(Image.open(d / f"frame_{i:02d}.png"))
        np.testing.assert_array_equal(davis.frames.blurry[i, :, :, 0], png)


def test_davis_events_per_exposure(davis):
    """Half-open [start, end): 6007 / 5451 / 4835. The README's 6010 / 5452 / 4835 count the closed window
    [start, end]; the difference is exactly the events stamped at the exposure end."""
    vi = davis.events.view_index
    np.testing.assert_array_equal(vi[:, 1] - vi[:, 0], [6007, 5451, 4835])
    t, ex = davis.events.t, davis.frames.exposure_us
    closed = np.searchsorted(t, ex[:, 1], side="right") - vi[:, 0]
    np.testing.assert_array_equal(closed, [6010, 5452, 4835])
    on = [int(np.count_nonzero(davis.events.p[a:b] == 1)) for a, b in vi]
    np.testing.assert_array_equal(on, [4568, 4173, 3566])


def test_davis_default_keeps_exposures(shared_real, tmp_path):
    out = tmp_path / "s.h5"
    assert run_ingest("aedat4", shared_real / "davis346_lab" / "davis.aedat4", out, "--intrinsics", DAVIS_K) == 0
    s = read_scene(out)
    assert len(s.events) == 6007 + 5451 + 4835
    np.testing.assert_array_equal(s.events.view_index, [[0, 6007], [6007, 11458], [11458, 16293]])


@pytest.fixture(scope="module")
def shapes(shared_real, tmp_path_factory):
    d = shared_real / "ecd_shapes_rotation"
    out = tmp_path_factory.mktemp("shapes") / "s.h5"
    gt = d / "groundtruth_full_SER_Lie_poses.txt"
    assert run_ingest("txt", d, out, "--sensor-size", "240x180", "--groundtruth", str(gt), "--no-undistort") == 0
    return read_scene(out)


def test_ecd_shapes_events(shapes):
    ev = shapes.events
    assert len(ev) == 20_000
    assert (int(ev.t[0]), int(ev.t[-1])) == (2_097_134, 2_195_729)
    assert int(np.count_nonzero(ev.p == -1)) == 11_440 and int(np.count_nonzero(ev.p == 1)) == 8_560
    assert (int(ev.x.min()), int(ev.x.max()), int(ev.y.min()), int(ev.y.max())) == (0, 236, 14, 179)


def test_ecd_shapes_calibration(shapes):
    np.testing.assert_allclose(
        shapes.camera.K, [[199.092366542, 0, 132.692071378], [0, 198.82882047, 111.212660011], [0, 0, 1]]
    )
    np.testing.assert_array_equal(
        shapes.camera.distortion, [-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0]
    )


def test_ecd_groundtruth_is_camera_to_world(shapes, shared_real):
    """The GT quaternion is T_world_cam: the body angular velocity it implies over the event window matches
    motion.txt (the snippet's angular velocity); read as world-to-camera it does not."""
    tr = shapes.trajectory
    assert tr.t_us.shape == (11_883,)
    assert (int(tr.t_us[0]), int(tr.t_us[-1])) == (21_819, 59_807_416)
    sel = (tr.t_us >= shapes.events.t[0]) & (tr.t_us <= shapes.events.t[-1])
    assert int(np.count_nonzero(sel)) == 19
    r, t = tr.c2w[sel, :3, :3], tr.t_us[sel] / 1e6

    def body_rate(rot):
        rel = np.einsum("nji,njk->nik", rot[:-1], rot[1:])  # R_i^T R_{i+1}
        ang = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
        axis = np.stack([rel[:, 2, 1] - rel[:, 1, 2], rel[:, 0, 2] - rel[:, 2, 0], rel[:, 1, 0] - rel[:, 0, 1]], 1)
        axis /= 2 * np.sin(ang)[:, None]
        return (axis * (ang / np.diff(t))[:, None]).mean(axis=0)

    motion = np.loadtxt(shared_real / "ecd_shapes_rotation" / "motion.txt")
    as_c2w, as_w2c = body_rate(r), body_rate(np.transpose(r, (0, 2, 1)))
    cos = lambda a, b: float(a @ b / np.linalg.norm(a) / np.linalg.norm(b))  # noqa: E731
    assert cos(as_c2w, motion) > 0.97 and np.linalg.norm(as_c2w - motion) < 0.15
    assert cos(as_w2c, motion) < 0.5


def test_ecd_shapes_undistorted(shared_real, tmp_path):
    d = shared_real / "ecd_shapes_rotation"
    out = tmp_path / "s.h5"
    assert run_ingest("txt", d, out, "--sensor-size", "240x180") == 0
    s = read_scene(out)
    assert not s.camera.has_distortion
    assert len(s.events) == 20_000 - 1_698  # events outside the pinhole image after undistortion


def test_ecd_poster(shared_real, tmp_path):
    out = tmp_path / "s.h5"
    assert (
        run_ingest("txt", shared_real / "ecd_poster_rotation", out, "--sensor-size", "240x180", "--no-undistort") == 0
    )
    ev = read_scene(out).events
    assert len(ev) == 30_000
    assert (int(ev.t[0]), int(ev.t[-1])) == (636_764, 660_949)  # 0.660948999 s rounds to the µs
    assert int(np.count_nonzero(ev.p == -1)) == 16_757 and int(np.count_nonzero(ev.p == 1)) == 13_243
    assert (int(ev.x.min()), int(ev.x.max()), int(ev.y.min()), int(ev.y.max())) == (0, 239, 0, 179)


def test_ecd_slider_depth_frames_only(shared_real, tmp_path):
    d = shared_real / "ecd_slider_depth"
    out = tmp_path / "s.h5"
    assert run_ingest("txt", d, out, "--no-undistort") == 0
    s = read_scene(out)
    assert s.events is None
    assert s.frames.blurry.shape == (87, 180, 240, 1) and s.frames.exposure_us is None
    png = np.asarray(Image.open(d / "images" / "frame_00000042.png"))
    np.testing.assert_array_equal(s.frames.blurry[42, :, :, 0], png)
    np.testing.assert_allclose(s.camera.K[:2, 2], [130.424663379, 99.6864303447])
    tr = s.trajectory
    assert tr.t_us.shape == (339,) and (int(tr.t_us[0]), int(tr.t_us[-1])) == (22_292, 3_402_486)
    np.testing.assert_array_equal(tr.c2w[:, :3, :3], np.broadcast_to(np.eye(3), (339, 3, 3)))
    assert np.all(tr.c2w[:, 1:3, 3] == 0) and abs(tr.c2w[:, 0, 3].max() - 1.100) < 1e-3
    # undistorted by default: same frame count, calibration's distortion applied to the frames
    out2 = tmp_path / "u.h5"
    assert run_ingest("txt", d, out2) == 0
    s2 = read_scene(out2)
    assert not s2.camera.has_distortion and s2.frames.blurry.shape == (87, 180, 240, 1)
