"""Frames and events from two devices (issue 33 part 4): a homography from frame to event pixels and a time offset
between the clocks, given or estimated (``--frames-homography``, ``--time-offset-us``), on a pair simulated with a
known offset and homography (tests/ingest/two_clock.py)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.two_clock import EH, EW, FOCAL, make_pair

# the event camera's calibration, OpenCV convention (principal point at the sensor centre)
INTRINSICS = f"{FOCAL},{FOCAL},{(EW - 1) / 2},{(EH - 1) / 2}"
EXPOSURE, PERIOD, OFFSET = 20_000, 25_000, 123_457


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    return make_pair(tmp_path_factory.mktemp("pair"), n_frames=40, exposure_us=EXPOSURE, period_us=PERIOD,
                     offset_us=OFFSET)  # fmt: skip


def _covered(pair) -> np.ndarray:
    """Event pixels the frame camera sees, one pixel in from the edge of its footprint (bilinear edges)."""
    import cv2

    from tests.ingest.two_clock import FH, FW, H_FE

    m = cv2.warpPerspective(np.full((FH, FW), 255, np.uint8), H_FE, (EW, EH), flags=cv2.INTER_NEAREST)
    return cv2.erode(m, np.ones((3, 3), np.uint8)) > 0


def test_estimated_offset_and_homography(pair, tmp_path, capsys):
    """`--time-offset-us auto` recovers the simulated offset within a tenth of an exposure; the frames warped by
    the homography match the blurry frames rendered directly in the event sensor's grid; frame names are kept."""
    out = tmp_path / "scene.h5"
    code = run_ingest("h5", pair.h5, out, "--frames-homography", str(pair.homography), "--time-offset-us", "auto",
                      "--intrinsics", INTRINSICS)  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0, text
    s = read_scene(out)
    frame_clock_start = pair.mid_event_us - EXPOSURE // 2 - OFFSET
    estimated = s.frames.exposure_us[:, 0] - frame_clock_start
    assert np.all(estimated == estimated[0])
    assert abs(int(estimated[0]) - OFFSET) <= EXPOSURE / 10, (estimated[0], text)
    m = re.search(r"time offset estimated: (-?\d+) µs.*peak ratio ([\d.inf]+).*interval \[(-?\d+), (-?\d+)\]", text)
    assert m and int(m.group(1)) == estimated[0]
    assert int(m.group(3)) <= int(m.group(1)) <= int(m.group(4))
    assert "AMBIGUOUS" not in text
    # the homography: warped frames equal the directly rendered event-grid frames where the frame camera sees
    assert s.frames.blurry.shape == (40, EH, EW, 1)
    mask = _covered(pair)
    diff = np.abs(s.frames.blurry[..., 0].astype(float) - pair.blurry_event_grid.astype(float))[:, mask]
    assert diff.mean() < 2.5 and np.median(diff) <= 2, (diff.mean(), np.median(diff))
    assert s.frames.names == pair.names
    # events are never resampled: every event of the file inside the (moved) exposures is kept as it was
    assert s.events.view_index.shape == (40, 2)


def test_given_offset_moves_frames_exactly(pair, tmp_path):
    out = tmp_path / "scene.h5"
    assert run_ingest("h5", pair.h5, out, "--frames-homography", str(pair.homography), "--time-offset-us",
                      str(OFFSET), "--intrinsics", INTRINSICS) == 0  # fmt: skip
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.exposure_us[:, 0], pair.mid_event_us - EXPOSURE // 2)
    np.testing.assert_array_equal(s.frames.exposure_us[:, 1], pair.mid_event_us + EXPOSURE // 2)


def test_without_homography_frames_of_another_size_are_refused(pair, tmp_path, capsys):
    err = expect_failure(capsys, "h5", pair.h5, tmp_path / "s.h5", "--intrinsics", INTRINSICS)
    assert "frames are 64×48 but events.h5 says 48×36" in err


@pytest.mark.parametrize(
    ("content", "message"),
    [("1 0 0\n0 1 0\n", "a homography needs 9 numbers (3×3, row-major), found 6"),
     ("1 0 0 0 1 0 0 0 nan", "homography contains NaN/Inf"),
     ("1 2 3 2 4 6 0 0 1", "homography is singular"),
     ("1 0 x 0 1 0 0 0 1", "holds something that is not a number")],
)  # fmt: skip
def test_bad_homography_file(pair, tmp_path, capsys, content, message):
    h = tmp_path / "H.txt"
    h.write_text(content)
    err = expect_failure(capsys, "h5", pair.h5, tmp_path / "s.h5", "--frames-homography", str(h), "--intrinsics",
                         INTRINSICS)  # fmt: skip
    assert str(h) in err and message in err


def test_bad_time_offset(pair, tmp_path, capsys):
    err = expect_failure(capsys, "h5", pair.h5, tmp_path / "s.h5", "--time-offset-us", "soon")
    assert "--time-offset-us: expected an integer (µs), auto or auto:LO,HI, got 'soon'" in err
    err = expect_failure(capsys, "h5", pair.h5, tmp_path / "s.h5", "--frames-homography", str(pair.homography),
                         "--time-offset-us", "auto:5000000,6000000", "--intrinsics", INTRINSICS)  # fmt: skip
    assert "no offset in [5000000, 6000000] µs" in err


def test_the_synchronised_scene_trains(pair, tmp_path):
    """The whole chain on the ingested pair (homography, the offset given: its estimate is tested above): EDI, SfM
    in model mode from a COLMAP
    model written with the simulated camera poses (named after the sidecar's frames), init, a short training."""
    import json

    import pycolmap

    from eigs.artifacts.poses import read_poses
    from eigs.cli import main
    from tests.ingest.two_clock import DEPTH

    scene = tmp_path / "scene.h5"
    assert run_ingest("h5", pair.h5, scene, "--frames-homography", str(pair.homography), "--time-offset-us",
                      str(OFFSET), "--intrinsics", INTRINSICS) == 0  # fmt: skip
    edi = tmp_path / "b2" / "edi.h5"
    assert main(["edi", str(scene), "-o", str(edi), "--bins", "2", "--latent-dir", str(tmp_path / "b2" / "latent"),
                 "--threads", "1"]) == 0  # fmt: skip
    # the model: the event camera's K (COLMAP's pixel convention is ours), one image per frame, points on the plane
    rec = pycolmap.Reconstruction()
    cx, cy = (EW - 1) / 2 + 0.5, (EH - 1) / 2 + 0.5
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=EW, height=EH,
                                                    params=[FOCAL, FOCAL, cx, cy], camera_id=1))  # fmt: skip
    for v, name in enumerate(pair.names):
        w2c = np.linalg.inv(pair.c2w_mid[v])
        img = pycolmap.Image(name=name.split("/")[-1], camera_id=1, image_id=v + 1)
        rec.add_image_with_trivial_frame(img, pycolmap.Rigid3d(pycolmap.Rotation3d(w2c[:3, :3]), w2c[:3, 3]))
    rng = np.random.default_rng(0)
    for xy in rng.uniform(-3, 3, (300, 2)):
        rec.add_point3D(np.array([xy[0], xy[1], DEPTH]), pycolmap.Track(), np.array([128, 128, 128], np.uint8))
    model = tmp_path / "sparse"
    model.mkdir()
    rec.write(str(model))
    sfm = tmp_path / "b2" / "sfm"
    assert main(["sfm", str(scene), str(edi), "-o", str(sfm), "--mode", "model", "--model", str(model),
                 "--no-plot"]) == 0  # fmt: skip
    poses = read_poses(sfm)
    assert poses.mode == "model" and poses.valid.all()
    init = tmp_path / "b2" / "init.ply"
    assert main(["init", str(sfm), "-o", str(init), "--min-points", "100"]) == 0
    run = tmp_path / "b2" / "run"
    assert main(["train", str(scene), str(edi), str(sfm), str(init), "-o", str(run), "--method", "3dgs",
                 "--steps", "5", "--device", "cpu"]) == 0  # fmt: skip
    assert (run / "model.ply").is_file()
    assert json.loads((sfm / "report.json").read_text())["model"]["matched"] == 40
