"""Prophesee RAW (EVT 2.0 / 2.1 / 3.0) and DAT files encoded by tests/ingest/prophesee_writer.py from known events."""

from __future__ import annotations

import numpy as np
import pytest

from eigs.ingest.prophesee import _State, decode, read_header
from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest
from tests.ingest.prophesee_writer import encode_evt3, known_events, write_dat, write_raw

PW, PH = 64, 48  # wide enough for EVT 3.0 vectors and EVT 2.1 masks
K_OPT = "50,50,32,24"


def _decoded(path, chunk_bytes):
    h = read_header(path)
    parts = list(decode(path, h, chunk_bytes))
    return tuple(np.concatenate([c[k] for c in parts]) for k in range(4))


@pytest.mark.parametrize("encoding", ["evt2", "evt21", "evt3", "dat"])
@pytest.mark.parametrize("chunk_bytes", [1 << 23, 64, 1000])
def test_decodes_known_events_exactly(tmp_path, encoding, chunk_bytes):
    """Exact round trip, also with tiny chunks (decoder state carried across every kind of word boundary)."""
    ev = known_events(3000, PW, PH, t0=123_456, seed=1)
    if encoding == "dat":
        f = tmp_path / "rec.dat"
        write_dat(f, *ev, PW, PH)
    else:
        f = tmp_path / "rec.raw"
        write_raw(f, encoding, *ev, PW, PH)
    got = _decoded(f, chunk_bytes)
    for g, e, name in zip(got, ev, "xytp", strict=True):
        np.testing.assert_array_equal(g, e, err_msg=name)


def test_evt3_time_high_wraps(tmp_path):
    """t crosses 2^24 µs (EVT 3.0's 24-bit time) twice: the TIME_HIGH loops are counted."""
    ev = known_events(4000, PW, PH, t0=(1 << 24) - 200_000, seed=2, gap_us=60_000)
    assert ev[2][-1] > (2 << 24)
    f = tmp_path / "rec.raw"
    write_raw(f, "evt3", *ev, PW, PH)
    got = _decoded(f, 4096)
    np.testing.assert_array_equal(got[2], ev[2])


def test_evt2_time_high_wraps(tmp_path):
    ev = known_events(2000, PW, PH, t0=(1 << 34) - 5_000, seed=3)
    assert ev[2][-1] > (1 << 34)
    f = tmp_path / "rec.raw"
    write_raw(f, "evt2", *ev, PW, PH, old_header=True)
    np.testing.assert_array_equal(_decoded(f, 1 << 20)[2], ev[2])


def test_events_before_first_time_high_are_dropped_and_counted(tmp_path):
    ev = known_events(300, PW, PH, t0=5000, seed=4)
    body = encode_evt3(*ev, first_high=False)  # no TIME_HIGH until t crosses the next 4096 µs step
    f = tmp_path / "rec.raw"
    f.write_bytes(f"% format EVT3;height={PH};width={PW}\n% end\n".encode() + body)
    st = _State()
    h = read_header(f)
    parts = list(decode(f, h, 1 << 20, st))
    t = np.concatenate([c[2] for c in parts])
    first = int(np.searchsorted(ev[2], ((5000 >> 12) + 1) << 12))
    assert st.dropped == first > 0
    np.testing.assert_array_equal(t, ev[2][first:])


@pytest.mark.parametrize("encoding", ["evt2", "evt3", "dat"])
def test_ingest(tmp_path, capsys, encoding):
    ev = known_events(2000, PW, PH, t0=1000, seed=5)
    f = tmp_path / ("rec.dat" if encoding == "dat" else "rec.raw")
    if encoding == "dat":
        write_dat(f, *ev, PW, PH)
    else:
        write_raw(f, encoding, *ev, PW, PH)
    out = tmp_path / "s.h5"
    assert run_ingest("prophesee", f, out, "--intrinsics", K_OPT) == 0
    assert {"evt2": "EVT 2.0", "evt3": "EVT 3.0", "dat": "DAT"}[encoding] in capsys.readouterr().out
    s = read_scene(out)
    assert (s.camera.width, s.camera.height) == (PW, PH)
    np.testing.assert_array_equal(s.events.x, ev[0])
    np.testing.assert_array_equal(s.events.y, ev[1])
    np.testing.assert_array_equal(s.events.t, ev[2])
    np.testing.assert_array_equal(s.events.p, np.where(ev[3] == 1, 1, -1))


@pytest.mark.parametrize("encoding", ["evt2", "evt3"])
def test_t0_header_is_the_time_origin(tmp_path, capsys, encoding):
    """faery's ``% t0 <µs>`` line: the times are stored relative to it, and come back on its absolute clock."""
    ev = known_events(1500, PW, PH, t0=7_000_123, seed=8)
    f = tmp_path / "rec.raw"
    write_raw(f, encoding, *ev, PW, PH, t0=7_000_000)
    header = read_header(f)
    assert header.t0_us == 7_000_000
    stored = np.concatenate([c[2] for c in decode(f, header)])  # the words themselves: relative to t0
    np.testing.assert_array_equal(stored, ev[2] - 7_000_000)
    out = tmp_path / "s.h5"
    assert run_ingest("prophesee", f, out, "--intrinsics", K_OPT) == 0
    assert "header t0 7000000 µs" in capsys.readouterr().out
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.t, ev[2])
    np.testing.assert_array_equal(s.events.x, ev[0])


def test_t0_header_not_a_number_is_refused(tmp_path, capsys):
    f = tmp_path / "rec.raw"
    f.write_bytes(f"% format EVT3;height={PH};width={PW}\n% t0 12.5\n% end\n".encode())
    err = expect_failure(capsys, "prophesee", f, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert "header t0 '12.5' is not a whole number of µs" in err


def _raw(tmp_path, encoding="evt3", n=500, **kw):
    ev = known_events(n, PW, PH, t0=1000, seed=6)
    f = tmp_path / "rec.raw"
    write_raw(f, encoding, *ev, PW, PH, **kw)
    return f


@pytest.mark.parametrize(
    "case,expected",
    [
        ("cut word", "truncated: the file ends inside a 2-byte word"),
        ("undefined type", "undefined EVT 3.0 word type 0x9 at byte"),
        ("no encoding", "the header names no event encoding"),
        ("bad format", "header format 'EVT4'"),
        ("backwards", "timestamps go backwards at event"),
        ("outside", "outside the sensor"),
        ("no size", "does not state the sensor size"),
        ("extension", "unknown extension '.bin'"),
        ("dat polarity", "polarity 3 of the event at byte"),
        ("dat cut", "truncated: the file ends inside a 8-byte word"),
        ("dat version", "DAT version '1'"),
        ("evt2 undefined", "undefined EVT 2.0 word type 0x5"),
        ("header cut", "truncated header"),
    ],
)
def test_errors(tmp_path, capsys, case, expected):
    opts = ["--intrinsics", K_OPT]
    f = tmp_path / "rec.raw"
    if case == "cut word":
        f = _raw(tmp_path)
        f.write_bytes(f.read_bytes()[:-1])
    elif case == "undefined type":
        f = _raw(tmp_path)
        f.write_bytes(f.read_bytes() + bytes([0x00, 0x90]))
    elif case == "no encoding":
        f.write_bytes(b"% date today\n" + bytes(8))
    elif case == "bad format":
        f.write_bytes(b"% format EVT4;height=4;width=4\n% end\n" + bytes(8))
    elif case == "backwards":
        head = f"% format EVT3;height={PH};width={PW}\n% end\n".encode()
        words = [0x8000 | 5, 0x6000 | 100, 0x0000 | 3, 0x2000 | 4, 0x6000 | 50, 0x2000 | 5]
        f.write_bytes(head + np.asarray(words, "<u2").tobytes())
    elif case == "outside":
        head = f"% format EVT3;height={PH};width={PW}\n% end\n".encode()
        words = [0x8000 | 5, 0x6000 | 100, 0x0000 | 3, 0x2000 | PW]
        f.write_bytes(head + np.asarray(words, "<u2").tobytes())
    elif case == "no size":
        head = b"% evt 3.0\n"
        f.write_bytes(head + np.asarray([0x8000 | 5], "<u2").tobytes())
    elif case == "extension":
        f = tmp_path / "rec.bin"
        f.write_bytes(b"% evt 3.0\n")
    elif case.startswith("dat"):
        f = tmp_path / "rec.dat"
        ev = known_events(50, PW, PH, seed=7)
        write_dat(f, *ev, PW, PH)
        data = bytearray(f.read_bytes())
        if case == "dat polarity":
            data[-1] = 0x30
        elif case == "dat cut":
            data = data[:-3]
        else:
            data = bytearray(bytes(data).replace(b"% Version 2", b"% Version 1"))
        f.write_bytes(bytes(data))
    elif case == "evt2 undefined":
        f = _raw(tmp_path, "evt2")
        f.write_bytes(f.read_bytes() + np.asarray([0x5 << 28], "<u4").tobytes())
    elif case == "header cut":
        f.write_bytes(b"% format EVT3;height=4")
    err = expect_failure(capsys, "prophesee", f, tmp_path / "s.h5", *opts)
    assert expected in err, err
    assert err.startswith(f"eigs ingest: error: {f}: "), err
