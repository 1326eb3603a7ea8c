"""HDF5 event files: DSEC (Blosc-compressed, t_offset, ms_to_idx), flat, Monash and v2e layouts; sidecar frames."""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.fixtures import H, W, random_events, write_dsec_h5, write_frames

K_OPT = "20,21,5,3"  # fx, fy, cx, cy (OpenCV)


@pytest.fixture()
def events():
    return random_events(5000, t0=1_000)


def _expect_events(s, ev, offset=0):
    np.testing.assert_array_equal(s.events.x, ev.x)
    np.testing.assert_array_equal(s.events.y, ev.y)
    np.testing.assert_array_equal(s.events.t, ev.t_us + offset)
    np.testing.assert_array_equal(s.events.p, np.where(ev.p01 == 1, 1, -1))


def test_dsec_round_trip(tmp_path, events):
    src = tmp_path / "events.h5"
    write_dsec_h5(src, events, t_offset=0)
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT) == 0
    s = read_scene(out)
    _expect_events(s, events)
    assert s.events.view_index is None and s.frames is None
    assert (s.camera.width, s.camera.height) == (W, H)
    np.testing.assert_array_equal(s.camera.K, [[20, 0, 5.5], [0, 21, 3.5], [0, 0, 1]])


def test_dsec_t_offset_is_added(tmp_path, events):
    src = tmp_path / "events.h5"
    offset = 1_633_953_690_000_000
    shifted = random_events(5000, t0=1_000)
    shifted.t_us = events.t_us + offset
    write_dsec_h5(src, shifted, t_offset=offset)
    with h5py.File(src) as f:
        assert f["events/t"].dtype == np.uint32 and int(f["events/t"][0]) == int(events.t_us[0])
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT) == 0
    _expect_events(read_scene(out), events, offset)


def _sidecar(tmp_path, src, rows, n=3):
    px, names = write_frames(tmp_path, n)
    lines = ["# exposure_start_us exposure_end_us image"] + [
        f"{a} {b} {nm}" for (a, b), nm in zip(rows, names, strict=True)
    ]
    (tmp_path / (src.stem + ".frames.txt")).write_text("\n".join(lines) + "\n")
    return px


def test_sidecar_frames_and_view_index(tmp_path, events):
    src = tmp_path / "rec.h5"
    write_dsec_h5(src, events)
    t = events.t_us
    rows = [(int(t[100]), int(t[900])), (int(t[2000]), int(t[2500])), (int(t[2400]), int(t[3000]))]  # 2 overlap
    px = _sidecar(tmp_path, src, rows)
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT) == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.blurry, px)
    np.testing.assert_array_equal(s.frames.exposure_us, rows)
    # default --keep-events exposures: the events inside any exposure, half-open [start, end)
    inside = np.zeros(t.shape, bool)
    for a, b in rows:
        inside |= (t >= a) & (t < b)
    np.testing.assert_array_equal(s.events.t, t[inside])
    for v, (a, b) in enumerate(rows):
        lo, hi = s.events.view_index[v]
        assert np.all((s.events.t[lo:hi] >= a) & (s.events.t[lo:hi] < b))
        assert hi - lo == np.count_nonzero((t >= a) & (t < b))
    # --keep-events all keeps everything; the view index still covers each exposure
    out2 = tmp_path / "s2.h5"
    assert run_ingest("h5", src, out2, "--intrinsics", K_OPT, "--keep-events", "all") == 0
    s2 = read_scene(out2)
    _expect_events(s2, events)
    np.testing.assert_array_equal(s2.events.view_index, np.searchsorted(t, np.asarray(rows), side="left"))


def test_views_and_time_window(tmp_path, events):
    src = tmp_path / "rec.h5"
    write_dsec_h5(src, events)
    t = events.t_us
    rows = [(int(t[100]), int(t[900])), (int(t[2000]), int(t[2500])), (int(t[3000]), int(t[3500]))]
    px = _sidecar(tmp_path, src, rows)
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT, "--views", "1:", "--keep-events", "all") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.frames.blurry, px[1:])
    _expect_events(s, events)
    w0, w1 = int(t[1500]), int(t[3200])
    out2 = tmp_path / "s2.h5"
    code = run_ingest("h5", src, out2, "--intrinsics", K_OPT, "--time-window", f"{w0},{w1}", "--keep-events", "all")
    assert code == 0
    s2 = read_scene(out2)
    np.testing.assert_array_equal(s2.frames.exposure_us, rows[1:2])  # only view 1 lies inside the window
    np.testing.assert_array_equal(s2.events.t, t[(t >= w0) & (t < w1)])


def test_flat_layout_needs_a_unit(tmp_path, events, capsys):
    src = tmp_path / "flat.h5"
    with h5py.File(src, "w") as f:
        f["x"], f["y"], f["t"], f["p"] = events.x, events.y, events.t_us * 1000, events.p01  # ns
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT, "--sensor-size", f"{W}x{H}")
    assert "flat.h5: the time unit of the flat layout is not stated in the file; give --time-unit" in err
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT, "--sensor-size", f"{W}x{H}", "--time-unit", "ns") == 0
    _expect_events(read_scene(out), events)


def test_monash_layout_with_unit_attribute(tmp_path, events):
    src = tmp_path / "monash.h5"
    with h5py.File(src, "w") as f:
        f["events/xs"], f["events/ys"] = events.x.astype(np.int16), events.y.astype(np.int16)
        f["events/ts"] = events.t_us / 1e6  # float seconds
        f["events/ts"].attrs["unit"] = "s"
        f["events/ps"] = np.where(events.p01 == 1, 1, -1).astype(np.int8)  # ±1
        f.attrs["width"], f.attrs["height"] = W, H
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT) == 0
    _expect_events(read_scene(out), events)


def test_v2e_layout(tmp_path, events):
    src = tmp_path / "v2e.h5"
    with h5py.File(src, "w") as f:
        block = np.stack([events.t_us, events.x, events.y, events.p01], axis=1).astype(np.uint32)
        f.create_dataset("events", data=block, compression="gzip")
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", K_OPT, "--sensor-size", f"{W}x{H}") == 0
    _expect_events(read_scene(out), events)


def test_known_point_projection(tmp_path, events):
    """--intrinsics is OpenCV's convention: our K projects a point to OpenCV's pixel + 0.5."""
    import cv2

    src = tmp_path / "events.h5"
    write_dsec_h5(src, events)
    out = tmp_path / "s.h5"
    assert run_ingest("h5", src, out, "--intrinsics", "20.5,19.25,5.125,3.75") == 0
    K = read_scene(out).camera.K
    P = np.array([[0.3, -0.2, 2.0]])
    Kcv = np.array([[20.5, 0, 5.125], [0, 19.25, 3.75], [0, 0, 1.0]])
    uv_cv = cv2.projectPoints(P, np.zeros(3), np.zeros(3), Kcv, np.zeros(5))[0].reshape(2)
    uvw = K @ P[0]
    np.testing.assert_allclose(uvw[:2] / uvw[2], uv_cv + 0.5, atol=1e-12)


# --- bad inputs ---------------------------------------------------------------------------------------------------
def test_missing_file(tmp_path, capsys):
    err = expect_failure(capsys, "h5", tmp_path / "none.h5", tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "none.h5: no such file" in err


def test_not_hdf5(tmp_path, capsys):
    src = tmp_path / "junk.h5"
    src.write_bytes(b"not an hdf5 file" * 100)
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "junk.h5: not a readable HDF5 file" in err


def test_truncated_file(tmp_path, events, capsys):
    src = tmp_path / "events.h5"
    write_dsec_h5(src, random_events(200_000))
    data = src.read_bytes()
    src.write_bytes(data[: len(data) * 2 // 3])
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "events.h5: " in err and ("truncated or corrupted" in err or "not a readable HDF5 file" in err)


def test_corrupted_chunk(tmp_path, capsys):
    src = tmp_path / "events.h5"
    write_dsec_h5(src, random_events(200_000, seed=5))
    with h5py.File(src) as f:
        off = f["events/t"].id.get_chunk_info(0).byte_offset
    data = bytearray(src.read_bytes())
    data[off + 16 : off + 48] = b"\xff" * 32
    src.write_bytes(bytes(data))
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "events.h5: cannot read events 0–" in err and "truncated or corrupted" in err


def test_lengths_differ(tmp_path, events, capsys):
    src = tmp_path / "e.h5"
    with h5py.File(src, "w") as f:
        f["events/x"], f["events/y"], f["events/t"] = events.x, events.y[:-1], events.t_us.astype(np.uint32)
        f["events/p"] = events.p01
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT, "--sensor-size", f"{W}x{H}")
    assert "e.h5: event arrays differ in length" in err


def test_backwards(tmp_path, events, capsys):
    events.t_us[4000] = events.t_us[3990] - 1
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events, compress=False)
    with h5py.File(src, "a") as f:
        del f["ms_to_idx"]
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "e.h5: timestamps go backwards at event 4000" in err


def test_ms_to_idx_disagrees(tmp_path, events, capsys):
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events)
    with h5py.File(src, "a") as f:
        m = f["ms_to_idx"][()]
        m[5] += 1
        f["ms_to_idx"][...] = m
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "e.h5: ms_to_idx[5] = " in err and "disagrees with events/t read as µs" in err


def test_nan_time(tmp_path, events, capsys):
    src = tmp_path / "e.h5"
    with h5py.File(src, "w") as f:
        t = events.t_us / 1e6
        t[77] = np.nan
        f["x"], f["y"], f["t"], f["p"] = events.x, events.y, t, events.p01
        f["t"].attrs["unit"] = "s"
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT, "--sensor-size", f"{W}x{H}")
    assert "e.h5: timestamp of event 77 is nan (NaN/Inf)" in err


def test_bad_polarity(tmp_path, events, capsys):
    events.p01[12] = 2
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events)
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "e.h5: polarity of event 12 is 2; expected 0/1 or −1/+1" in err


def test_coordinate_outside_sensor(tmp_path, events, capsys):
    events.x[33] = W
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events)
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert f"e.h5: x of event 33 is {W}, outside the sensor (0 ≤ x < {W})" in err


def test_no_intrinsics(tmp_path, events, capsys):
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events)
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5")
    assert "e.h5: the source has no camera calibration; give --intrinsics" in err


def test_no_size(tmp_path, events, capsys):
    src = tmp_path / "e.h5"
    write_dsec_h5(src, events, size=False)
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "e.h5: the source does not state the sensor size; give --sensor-size" in err


def test_sidecar_backwards(tmp_path, events, capsys):
    src = tmp_path / "rec.h5"
    write_dsec_h5(src, events)
    _sidecar(tmp_path, src, [(5000, 6000), (4000, 4500), (7000, 8000)])
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "rec.frames.txt: exposure starts go backwards at frame 1" in err


def test_sidecar_missing_image(tmp_path, events, capsys):
    src = tmp_path / "rec.h5"
    write_dsec_h5(src, events)
    _sidecar(tmp_path, src, [(5000, 6000), (6000, 6500), (7000, 8000)])
    (tmp_path / "images" / "frame_00000002.png").unlink()
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "frame_00000002.png: missing image" in err


def test_exposure_offsets_need_timestamps(tmp_path, events, capsys):
    src = tmp_path / "rec.h5"
    write_dsec_h5(src, events)
    _sidecar(tmp_path, src, [(5000, 6000), (6000, 6500), (7000, 8000)])
    err = expect_failure(capsys, "h5", src, tmp_path / "s.h5", "--intrinsics", K_OPT, "--exposure-us=-10,10")
    assert "--exposure-us: " in err and "rec.h5 already states exposure times" in err
