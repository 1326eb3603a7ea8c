"""AEDAT 4 recordings written by the tests (tests/ingest/aedat4_writer.py) and read through the ``aedat`` decoder."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.aedat4_writer import event_packet, frame_packet, write_aedat4
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import H, W, random_events

T0 = 1_633_953_690_975_950  # absolute Unix µs, as DAVIS recordings store them
K_OPT = "30,30,5,3"


def _recording(path, n=4000, frames=((500, 1500), (9000, 10000), (15000, 17000)), fmt=0, seed=0):
    ev = random_events(n, seed=seed, t0=T0)
    rng = np.random.default_rng(seed)
    channels = {0: 1, 16: 3, 24: 4}[fmt]
    px = rng.integers(0, 256, (len(frames), H, W, channels), dtype=np.uint8)
    exposures = [(T0 + a, T0 + b) for a, b in frames]
    packets, k = [], 0
    for i in range(0, n, 700):  # events in several packets, frames interleaved by time
        sl = slice(i, i + 700)
        packets.append((0, event_packet(ev.t_us[sl], ev.x[sl], ev.y[sl], ev.p01[sl])))
        while k < len(frames) and exposures[k][1] <= ev.t_us[min(i + 699, n - 1)]:
            img = px[k, :, :, 0] if channels == 1 else px[k]
            packets.append((1, frame_packet((exposures[k][0] + exposures[k][1]) // 2, exposures[k], img, fmt)))
            k += 1
    for j in range(k, len(frames)):
        img = px[j, :, :, 0] if channels == 1 else px[j]
        packets.append((1, frame_packet((exposures[j][0] + exposures[j][1]) // 2, exposures[j], img, fmt)))
    write_aedat4(path, W, H, packets)
    return ev, px, np.asarray(exposures, np.int64)


def test_round_trip(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    ev, px, exposures = _recording(src)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat4", src, out, "--intrinsics", K_OPT, "--keep-events", "all") == 0
    assert "streams 0:events, 1:frame" in capsys.readouterr().out
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, ev.t_us)  # absolute µs kept
    np.testing.assert_array_equal(s.events.x, ev.x)
    np.testing.assert_array_equal(s.events.y, ev.y)
    np.testing.assert_array_equal(s.events.p, np.where(ev.p01 == 1, 1, -1))
    np.testing.assert_array_equal(s.frames.blurry, px)
    np.testing.assert_array_equal(s.frames.exposure_us, exposures)
    np.testing.assert_array_equal(s.events.view_index, np.searchsorted(ev.t_us, exposures, side="left"))


def test_default_keeps_exposure_events(tmp_path):
    src = tmp_path / "rec.aedat4"
    ev, _, exposures = _recording(src)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat4", src, out, "--intrinsics", K_OPT) == 0
    s = read_scene(out)
    t = ev.t_us
    inside = np.zeros(t.shape, bool)
    for a, b in exposures:
        inside |= (t >= a) & (t < b)
    np.testing.assert_array_equal(s.events.t, t[inside])
    counts = s.events.view_index[:, 1] - s.events.view_index[:, 0]
    np.testing.assert_array_equal(counts, [np.count_nonzero((t >= a) & (t < b)) for a, b in exposures])


@pytest.mark.parametrize("fmt", [16, 24])
def test_colour_frames(tmp_path, fmt):
    """AEDAT stores BGR(A); the scene holds RGB, alpha composited on black."""
    src = tmp_path / "rec.aedat4"
    _, px, _ = _recording(src, fmt=fmt)  # px as written (BGR / BGRA)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat4", src, out, "--intrinsics", K_OPT, "--views", "0,2") == 0
    s = read_scene(out)
    rgb = px[[0, 2], :, :, 2::-1].astype(np.uint32)
    if fmt == 24:
        a = px[[0, 2], :, :, 3:].astype(np.uint32)
        rgb = (rgb * a + 127) // 255
    np.testing.assert_array_equal(s.frames.blurry, rgb.astype(np.uint8))


# --- bad inputs ---------------------------------------------------------------------------------------------------
def test_missing(tmp_path, capsys):
    err = expect_failure(capsys, "aedat4", tmp_path / "no.aedat4", tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "no.aedat4: no such file" in err


def test_wrong_magic(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    src.write_bytes(b"#!AER-DAT2.0\r\n# jAER\r\n" + bytes(100))
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.aedat4: not an AEDAT 4 file (starts with" in err


def test_truncated(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    _recording(src)
    data = src.read_bytes()
    src.write_bytes(data[: len(data) - 1000])
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.aedat4: truncated or corrupted AEDAT 4 file" in err


def test_corrupted_header(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    _recording(src)
    data = bytearray(src.read_bytes())
    data[14:18] = (10**9).to_bytes(4, "little")  # IOHeader length beyond the file
    src.write_bytes(bytes(data))
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.aedat4: not a readable AEDAT 4 file" in err


def test_backwards(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    t = np.array([T0 + 10, T0 + 20, T0 + 15], np.int64)
    z = np.zeros(3, np.int64)
    write_aedat4(
        src, W, H, [(0, event_packet(t[:2], z[:2], z[:2], z[:2])), (0, event_packet(t[2:], z[2:], z[2:], z[2:]))]
    )
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.aedat4: event timestamps go backwards near event 2" in err


def test_region_of_interest_frame(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    img = np.zeros((H - 2, W), np.uint8)
    write_aedat4(src, W, H, [(1, frame_packet(T0, (T0, T0 + 5), img, 0, offset=(0, 2)))])
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.aedat4: frame 0 is a region of interest, not the full 11×7 sensor" in err


def test_needs_intrinsics(tmp_path, capsys):
    src = tmp_path / "rec.aedat4"
    _recording(src)
    err = expect_failure(capsys, "aedat4", src, tmp_path / "s.h5")
    assert "rec.aedat4: the source has no camera calibration; give --intrinsics" in err


def test_known_point_projection(tmp_path):
    """--intrinsics is OpenCV's convention: our K projects a point to OpenCV's pixel + 0.5."""
    import cv2

    src = tmp_path / "rec.aedat4"
    _recording(src)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat4", src, out, "--intrinsics", "30.5,29,5.25,3.5") == 0
    K = read_scene(out).camera.K
    P = np.array([[0.05, -0.04, 1.2]])
    Kcv = np.array([[30.5, 0, 5.25], [0, 29, 3.5], [0, 0, 1.0]])
    uv = cv2.projectPoints(P, np.zeros(3), np.zeros(3), Kcv, np.zeros(5))[0].reshape(2)
    uvw = K @ P[0]
    np.testing.assert_allclose(uvw[:2] / uvw[2], uv + 0.5, atol=1e-12)
