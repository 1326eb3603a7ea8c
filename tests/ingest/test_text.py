"""ECD / v2e text recordings: events, frames, calibration, ground truth, undistortion; bad inputs."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import H, W, random_events, random_rotation, write_frames, write_text_events

V2E_HEADER = [
    "#!events.txt",
    "# This is a text DVS created by v2e (see https://github.com/SensorsINI/v2e)",
    "# Format is time (float s), x, y, polarity (0=OFF, 1=ON)",
    "# Creation time: 2024-01-01 00:00:00",
    "# Creation time: 1704067200",
    "# Username: tester",
]
CALIB = "20.0 21.0 5.0 3.0 0.0 0.0 0.0 0.0 0.0\n"


@pytest.fixture()
def recording(tmp_path):
    folder = tmp_path / "seq"
    folder.mkdir()
    ev = random_events(3000, t0=50_000)
    write_text_events(folder / "events.txt", ev)
    (folder / "calib.txt").write_text(CALIB)
    return folder, ev


def test_round_trip(recording, tmp_path, capsys):
    folder, ev = recording
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out, "--sensor-size", f"{W}x{H}") == 0
    text = capsys.readouterr().out
    assert "events: 3,000 kept of 3,000 read (all)" in text
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, ev.t_us)
    np.testing.assert_array_equal(s.events.x, ev.x)
    np.testing.assert_array_equal(s.events.y, ev.y)
    np.testing.assert_array_equal(s.events.p, np.where(ev.p01 == 1, 1, -1))
    np.testing.assert_array_equal(s.camera.K, [[20, 0, 5.5], [0, 21, 3.5], [0, 0, 1]])
    assert s.frames is None and s.trajectory is None


def test_v2e_header_and_flag_column(tmp_path):
    ev = random_events(500)
    lines = V2E_HEADER + [
        f"{t / 1e6:.6f} {x} {y} {p} {i % 2}"
        for i, (t, x, y, p) in enumerate(
            zip(ev.t_us.tolist(), ev.x.tolist(), ev.y.tolist(), ev.p01.tolist(), strict=True)
        )
    ]
    f = tmp_path / "v2e-dvs-events.txt"
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "s.h5"
    assert run_ingest("txt", f, out, "--sensor-size", f"{W}x{H}", "--intrinsics", "10,10,5,3") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, ev.t_us)
    np.testing.assert_array_equal(s.events.p, np.where(ev.p01 == 1, 1, -1))


def test_time_rounding(tmp_path):
    """Seconds → nearest ns → nearest µs (half up); float noise in the text does not matter."""
    f = tmp_path / "events.txt"
    f.write_text("2.097134001 1 2 0\n2.0971345 1 2 1\n2.1957200009999998 3 4 1\n2.19572049 0 0 0\n")
    out = tmp_path / "s.h5"
    assert run_ingest("txt", f, out, "--sensor-size", f"{W}x{H}", "--intrinsics", "10,10,5,3") == 0
    np.testing.assert_array_equal(read_scene(out).events.t, [2097134, 2097135, 2195720, 2195720])


@pytest.mark.parametrize("sep,end", [("\t", "\n"), ("  ", "\n"), (" ", " \n"), (" ", "\r\n")])
def test_separators(tmp_path, sep, end):
    f = tmp_path / "events.txt"
    f.write_bytes(
        ("# c" + end + sep.join(["0.000001", "1", "2", "0"]) + end + sep.join(["0.5", "3", "4", "1"]) + end).encode()
    )
    out = tmp_path / "s.h5"
    assert run_ingest("txt", f, out, "--sensor-size", f"{W}x{H}", "--intrinsics", "10,10,5,3") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, [1, 500_000])
    np.testing.assert_array_equal(s.events.x, [1, 3])


def test_mixed_separators(tmp_path, capsys):
    f = _events_file(tmp_path, "0.1 1 2 0\n0.2  3 4 1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: line 2 separates fields differently from the first line" in err


def test_frames_exposure_offsets_and_groundtruth(recording, tmp_path):
    from scipy.spatial.transform import Rotation

    folder, ev = recording
    px, names = write_frames(folder, 4, channels=3)
    ft = ev.t_us[[200, 900, 1500, 2600]]
    (folder / "images.txt").write_text("".join(f"{t / 1e6:.6f} {n}\n" for t, n in zip(ft, names, strict=True)))
    rng = np.random.default_rng(9)
    rot = random_rotation(rng, 6)
    q = Rotation.from_matrix(rot).as_quat()  # x y z w
    gt_t = np.arange(6) * 0.01 + 0.05
    pos = rng.normal(size=(6, 3))
    (folder / "groundtruth.txt").write_text(
        "".join(
            f"{t:.9f} {p[0]} {p[1]} {p[2]} {a[0]} {a[1]} {a[2]} {a[3]}\n" for t, p, a in zip(gt_t, pos, q, strict=True)
        )
    )
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out, "--exposure-us=-300,200") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.blurry, px)
    np.testing.assert_array_equal(s.frames.exposure_us, np.stack([ft - 300, ft + 200], axis=1))
    t = ev.t_us
    inside = np.zeros(t.shape, bool)
    for a, b in s.frames.exposure_us:
        inside |= (t >= a) & (t < b)
    np.testing.assert_array_equal(s.events.t, t[inside])  # default: keep events inside exposures
    np.testing.assert_array_equal(s.trajectory.t_us, np.rint(gt_t * 1e6).astype(np.int64))
    assert np.abs(s.trajectory.c2w[:, :3, :3] - rot).max() < 1e-9
    np.testing.assert_allclose(s.trajectory.c2w[:, :3, 3], pos)


def test_frames_without_exposure_keep_their_timestamps(recording, tmp_path, capsys):
    """images.txt without --exposure-us: the frames are instants with their timestamps (µs); events are kept."""
    folder, ev = recording
    px, names = write_frames(folder, 3, channels=1)
    ft_s = [0.0, 0.038766001, 0.077531001]  # ECD slider_depth's first three times
    (folder / "images.txt").write_text("".join(f"{t:.9f} {n}\n" for t, n in zip(ft_s, names, strict=True)))
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out) == 0
    assert "frames are instants" in capsys.readouterr().out
    s = read_scene(out)
    assert s.frames.exposure_us is None
    np.testing.assert_array_equal(s.frames.t_us, [0, 38_766, 77_531])
    np.testing.assert_array_equal(s.frames.blurry, px)
    np.testing.assert_array_equal(s.events.t, ev.t_us)
    out2 = tmp_path / "s2.h5"  # --views keeps the timestamps of the kept frames
    assert run_ingest("txt", folder, out2, "--views", "1:3") == 0
    np.testing.assert_array_equal(read_scene(out2).frames.t_us, [38_766, 77_531])


def test_rgb_only_folder(tmp_path):
    folder = tmp_path / "slider"
    folder.mkdir()
    px, names = write_frames(folder, 3)
    (folder / "images.txt").write_text("".join(f"{0.04 * i:.9f} {n}\n" for i, n in enumerate(names)))
    (folder / "calib.txt").write_text(CALIB)
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out) == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.blurry, px)
    assert s.events is None and s.frames.exposure_us is None


def test_known_point_projection_through_calib(recording, tmp_path):
    import cv2

    folder, _ = recording
    (folder / "calib.txt").write_text("20.5 19.25 5.125 3.75 0 0 0 0 0\n")
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out, "--sensor-size", f"{W}x{H}") == 0
    K = read_scene(out).camera.K
    P = np.array([[-0.25, 0.1, 1.5]])
    Kcv = np.array([[20.5, 0, 5.125], [0, 19.25, 3.75], [0, 0, 1.0]])
    uv = cv2.projectPoints(P, np.zeros(3), np.zeros(3), Kcv, np.zeros(5))[0].reshape(2)
    uvw = K @ P[0]
    np.testing.assert_allclose(uvw[:2] / uvw[2], uv + 0.5, atol=1e-12)


# --- undistortion -------------------------------------------------------------------------------------------------
DIST_CALIB = (60.0, 61.0, 31.3, 23.7, -0.30, 0.12, 0.001, -0.002, 0.0)
DW, DH = 64, 48


def _distorted_recording(tmp_path):
    folder = tmp_path / "dist"
    folder.mkdir()
    (folder / "calib.txt").write_text(" ".join(map(str, DIST_CALIB)) + "\n")
    return folder


def test_event_lookup_matches_independent_inversion(tmp_path):
    """Each event goes to the rounded undistorted position found by inverting OpenCV's projectPoints."""
    import cv2
    from scipy.optimize import least_squares

    from eigs.ingest.options import parse_calibration_numbers
    from eigs.ingest.undistort import Undistorter

    K, dist = parse_calibration_numbers(list(DIST_CALIB), "calib")
    und = Undistorter(K, dist, DW, DH)
    fx, fy, cx, cy = DIST_CALIB[:4]
    Kcv = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    rng = np.random.default_rng(4)
    checked = 0
    for x0, y0 in zip(rng.integers(0, DW, 60), rng.integers(0, DH, 60), strict=True):

        def resid(q, x0=x0, y0=y0):
            uv = cv2.projectPoints(np.array([[q[0], q[1], 1.0]]), np.zeros(3), np.zeros(3), Kcv, dist)[0]
            return uv.reshape(2) - [x0, y0]

        sol = least_squares(resid, [(x0 - cx) / fx, (y0 - cy) / fy], xtol=1e-15, ftol=1e-15)
        u, v = sol.x[0] * fx + cx, sol.x[1] * fy + cy
        flat = und.event_lut[y0 * DW + x0]
        inside = 0 <= round(u) < DW and 0 <= round(v) < DH
        if abs(u - round(u) - 0.5) < 1e-6 or abs(v - round(v) - 0.5) < 1e-6:
            continue  # a tie: either neighbour is right
        if inside:
            assert flat == round(v) * DW + round(u), (x0, y0, u, v)
            checked += 1
        else:
            assert flat == -1
    assert checked > 30


def test_frames_and_events_undistort_consistently(tmp_path):
    """A bright dot in a distorted frame and an event at the same sensor pixel land on the same undistorted pixel."""
    folder = _distorted_recording(tmp_path)
    x0, y0 = 9, 8  # near a corner, where distortion is strong
    img = np.zeros((1, DH, DW, 1), np.uint8)
    yy, xx = np.mgrid[0:DH, 0:DW]
    img[0, :, :, 0] = np.clip(255 * np.exp(-((xx - x0) ** 2 + (yy - y0) ** 2) / 2.0), 0, 255).astype(np.uint8)
    from tests.ingest.fixtures import save_png

    save_png(folder / "images" / "f0.png", img[0])
    (folder / "images.txt").write_text("0.001 images/f0.png\n")
    (folder / "events.txt").write_text(f"0.0010 {x0} {y0} 1\n0.0011 {DW - 1} 0 1\n")
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out, "--keep-events", "all") == 0
    s = read_scene(out)
    assert not s.camera.has_distortion
    assert len(s.events) == 1  # the corner event falls outside the pinhole image and is dropped
    u, v = int(s.events.x[0]), int(s.events.y[0])
    f = s.frames.blurry[0, :, :, 0].astype(float)
    i, j = np.unravel_index(np.argmax(f), f.shape)
    assert abs(int(j) - u) <= 1 and abs(int(i) - v) <= 1, ((j, i), (u, v))
    assert (u, v) != (x0, y0)


def test_no_undistort_keeps_distortion(tmp_path):
    folder = _distorted_recording(tmp_path)
    (folder / "events.txt").write_text(f"0.0010 3 4 1\n0.0011 {DW - 1} 0 0\n")
    out = tmp_path / "s.h5"
    assert run_ingest("txt", folder, out, "--sensor-size", f"{DW}x{DH}", "--no-undistort") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.camera.distortion, DIST_CALIB[4:])
    np.testing.assert_array_equal(s.events.x, [3, DW - 1])


# --- bad inputs ---------------------------------------------------------------------------------------------------
OPTS = ("--sensor-size", f"{W}x{H}")


def _events_file(tmp_path, text):
    f = tmp_path / "events.txt"
    f.write_text(text)
    (tmp_path / "calib.txt").write_text(CALIB)
    return f


def test_missing_source(tmp_path, capsys):
    err = expect_failure(capsys, "txt", tmp_path / "nothing", tmp_path / "s.h5")
    assert "nothing: no such file or folder" in err


def test_empty_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    err = expect_failure(capsys, "txt", tmp_path / "empty", tmp_path / "s.h5")
    assert "empty: no event file (events.txt or v2e-dvs-events.txt) and no images.txt" in err


def test_truncated_last_line(tmp_path, capsys):
    f = _events_file(tmp_path, "# header\n0.1 1 2 0\n0.2 3 4 1\n0.3 5")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: line 4 has 2 fields, expected 4 (truncated)" in err


def test_not_numbers(tmp_path, capsys):
    f = _events_file(tmp_path, "0.1 1 2 0\n0.2 three 4 1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: line 2 is not 't x y p' numbers" in err


def test_backwards(tmp_path, capsys):
    f = _events_file(tmp_path, "#c\n0.1 1 2 0\n0.3 3 4 1\n0.2 5 5 1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: timestamps go backwards at line 4 (event 2)" in err


def test_nan(tmp_path, capsys):
    f = _events_file(tmp_path, "0.1 1 2 0\nnan 3 4 1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: timestamp of event 1 (line 2) is nan (NaN/Inf)" in err


def test_outside_sensor(tmp_path, capsys):
    f = _events_file(tmp_path, f"0.1 1 2 0\n0.2 3 {H} 1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert f"events.txt: y of event 1 (line 2) is {H}, outside the sensor (0 ≤ y < {H})" in err


def test_bad_polarity(tmp_path, capsys):
    f = _events_file(tmp_path, "0.1 1 2 0\n0.2 3 4 -1\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "events.txt: polarity mixes 0 and −1 values" in err


def test_bad_calib(tmp_path, capsys):
    f = _events_file(tmp_path, "0.1 1 2 0\n")
    (tmp_path / "calib.txt").write_text("1 2 3\n")
    err = expect_failure(capsys, "txt", f, tmp_path / "s.h5", *OPTS)
    assert "calib.txt: expected 4, 8 or 9 numbers (fx fy cx cy [k1 k2 p1 p2 [k3]]), got 3" in err


def test_groundtruth_backwards(recording, tmp_path, capsys):
    folder, _ = recording
    (folder / "groundtruth.txt").write_text("0.1 0 0 0 0 0 0 1\n0.3 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 0 1\n")
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS)
    assert "groundtruth.txt: timestamps go backwards or repeat at pose 2" in err


def test_groundtruth_nan_and_bad_quaternion(recording, tmp_path, capsys):
    folder, _ = recording
    gt = folder / "groundtruth.txt"
    gt.write_text("0.1 0 nan 0 0 0 0 1\n")
    assert "groundtruth.txt: line 1 has NaN/Inf" in expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS)
    gt.write_text("0.1 0 0 0 0 0 0 2\n")
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS)
    assert "groundtruth.txt: pose 0 has a quaternion of norm 2.000000, not a unit quaternion" in err


def test_groundtruth_option_missing(recording, tmp_path, capsys):
    folder, _ = recording
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS, "--groundtruth", str(tmp_path / "gt.txt"))
    assert "gt.txt: no such file" in err


def test_images_txt_missing_image(recording, tmp_path, capsys):
    folder, _ = recording
    _, names = write_frames(folder, 2)
    (folder / "images.txt").write_text(f"0.0 {names[0]}\n0.04 {names[1]}\n0.08 images/nope.png\n")
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", "--keep-events", "all")
    assert "nope.png: missing image" in err


def test_images_txt_backwards(recording, tmp_path, capsys):
    folder, _ = recording
    _, names = write_frames(folder, 2)
    (folder / "images.txt").write_text(f"0.04 {names[0]}\n0.0 {names[1]}\n")
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5")
    assert "images.txt: timestamps go backwards at frame 1" in err


def test_keep_exposures_needs_exposures(recording, tmp_path, capsys):
    folder, _ = recording
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS, "--keep-events", "exposures")
    assert "--keep-events exposures needs exposure times, which the source lacks; give --exposure-us" in err


def test_bad_option_values(recording, tmp_path, capsys):
    folder, _ = recording
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", "--sensor-size", "11by7")
    assert "--sensor-size: expected WIDTHxHEIGHT" in err
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS, "--time-window", "5,2")
    assert "--time-window: END must be after START" in err
    err = expect_failure(capsys, "txt", folder, tmp_path / "s.h5", *OPTS, "--intrinsics", "1,2,3")
    assert "--intrinsics: expected 4, 8 or 9 numbers" in err
