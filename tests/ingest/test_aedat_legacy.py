"""AEDAT 3.1 and 2.0 files written here from known content, following the format pages (cAER "AEDAT 3.1", jAER
"AEDAT 2.0"), read with ``--format aedat``."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from eigs.scene import read_scene
from tests.ingest.conftest import expect_failure, run_ingest

K_OPT = "200,200,120,90"


def _events(n, w, h, seed=0, t0=1000):
    rng = np.random.default_rng(seed)
    t = t0 + np.cumsum(rng.integers(0, 50, n)).astype(np.int64)
    return rng.integers(0, w, n), rng.integers(0, h, n), t, rng.integers(0, 2, n)


def write_aedat31(path, ev, frames, w=240, h=180, overflow_at=None):
    """Polarity packets of 300 events (some invalid ones mixed in), frame packets (1 channel), an IMU packet."""
    x, y, t, p = ev
    out = [b"#!AER-DAT3.1\r\n", b"#Format: RAW\r\n", b"#Source 1: DAVIS240C\r\n", b"#!END-HEADER\r\n"]

    def packet(etype, esize, events: bytes, num, ovf=0):
        return struct.pack("<hhiiiiii", etype, 1, esize, 4, ovf, num, num, num) + events

    k = 0
    fi = 0
    # packets of ≤ 300 events; a packet never spans a timestamp overflow (cAER starts a new one)
    cuts = sorted({*range(0, len(t), 300), *np.flatnonzero(np.diff(t >> 31)) + 1, len(t)})
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        sl = slice(a, b)
        data = (x[sl].astype(np.uint32) << 17) | (y[sl].astype(np.uint32) << 2) | (p[sl].astype(np.uint32) << 1) | 1
        tt = t[sl]
        ovf = 0
        if overflow_at is not None:
            ovf = int(tt[0] >> 31)
            tt = tt & 0x7FFFFFFF
        rec = np.zeros(len(data) + 1, dtype=[("d", "<u4"), ("t", "<i4")])
        rec["d"][:-1], rec["t"][:-1] = data, tt
        rec["d"][-1], rec["t"][-1] = (5 << 17) | (5 << 2), tt[-1]  # an invalid event (valid bit 0)
        out.append(packet(1, 8, rec.tobytes(), len(rec), ovf))
        while fi < len(frames) and frames[fi][1] <= t[sl][-1]:
            (s, e, img) = frames[fi]
            head = struct.pack("<9i", 1 | (1 << 1), s - 10, e + 10, s, e, w, h, 0, 0)
            pix = (img.astype(np.uint16) << 8) | 0x3F  # 16-bit values; the low byte must be dropped
            out.append(packet(2, 36 + 2 * w * h, head + pix.astype("<u2").tobytes(), 1))
            fi += 1
        k += 1
        if k == 2:
            out.append(packet(3, 40, bytes(40 * 2), 2))  # IMU6 samples
    path.write_bytes(b"".join(out))


def _frames(n, w, h, t, seed=1):
    rng = np.random.default_rng(seed)
    span = (int(t[0]), int(t[-1]))
    starts = np.linspace(span[0] + 500, span[1] - 3000, n).astype(np.int64)
    return [(int(s), int(s) + 2000, rng.integers(0, 256, (h, w), dtype=np.uint8)) for s in starts]


def test_aedat31_round_trip(tmp_path):
    ev = _events(3000, 240, 180)
    frames = _frames(3, 240, 180, ev[2])
    f = tmp_path / "rec.aedat"
    write_aedat31(f, ev, frames)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat", f, out, "--intrinsics", K_OPT, "--keep-events", "all") == 0
    s = read_scene(out)
    np.testing.assert_array_equal(s.events.x, ev[0])
    np.testing.assert_array_equal(s.events.y, ev[1])
    np.testing.assert_array_equal(s.events.t, ev[2])
    np.testing.assert_array_equal(s.events.p, np.where(ev[3] == 1, 1, -1))
    np.testing.assert_array_equal(s.frames.blurry[..., 0], np.stack([fr[2] for fr in frames]))
    np.testing.assert_array_equal(s.frames.exposure_us, [[a, b] for a, b, _ in frames])


def test_aedat31_timestamp_overflow(tmp_path):
    ev = _events(900, 240, 180, t0=(1 << 31) - 20_000)
    f = tmp_path / "rec.aedat"
    write_aedat31(f, ev, [], overflow_at=True)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat", f, out, "--intrinsics", K_OPT) == 0
    np.testing.assert_array_equal(read_scene(out).events.t, ev[2])


def write_aedat20(path, ev, h=180, chip="eu.seebetter.ini.chips.davis.DAVIS240C", frames=(), w=240, seed=5):
    """jAER DAVIS records (big-endian address + timestamp) following jAER's DavisChip layout: DVS columns mirrored
    (x address = W − 1 − column), rows counted from the bottom; APS reset/signal reads of ``frames`` ((start, end,
    (H, W) uint8 image): last reset read at ``start``, first signal read at ``end``, reset − signal = 4·image + 0..3);
    mixed in: an IMU sample (7 records), a special event, a deprecated third-cycle read, signal reads left over from
    a frame before the file and an unfinished frame (resets only) at the end."""
    rng = np.random.default_rng(seed)
    x, y, t, p = ev
    dt = np.dtype([("a", ">u4"), ("t", ">i4")])
    a = ((h - 1 - y).astype(np.uint32) << 22) | ((w - 1 - x).astype(np.uint32) << 12) | (p.astype(np.uint32) << 11)
    parts = [(np.asarray(t, np.int64), a.astype(np.uint32))]
    col, row = np.meshgrid(np.arange(w), np.arange(h))
    order = np.argsort(-(row * w + col), axis=None)  # any order; this one runs from the top right pixel

    def aps(cycle, values, t0, t1):
        rr, cc = row.ravel()[order], col.ravel()[order]
        addr = (1 << 31) | ((h - 1 - rr) << 22) | (cc << 12) | (cycle << 10) | values.ravel()[order]
        return np.linspace(t0, t1, rr.size).astype(np.int64), addr.astype(np.uint32)

    for s, e, img in frames:
        cds = img.astype(np.int64) * 4 + rng.integers(0, 4, img.shape)
        signal = rng.integers(0, 1024 - cds)
        parts.append(aps(0, signal + cds, s - 3000, s))  # reset reads end at the exposure start
        parts.append(aps(1, signal, e, e + 3000))  # signal reads start at the exposure end
    parts.append((np.full(7, t[5]), np.full(7, 0x80000C00, np.uint32) | (np.arange(7, dtype=np.uint32) << 28)))
    parts.append((np.array([t[20]]), np.array([1 << 10], np.uint32)))  # external input event
    parts.append((np.array([t[30]]), np.array([(1 << 31) | (2 << 10) | (3 << 12) | 17], np.uint32)))  # "C" read
    first, last = min(int(q[0].min()) for q in parts), max(int(q[0].max()) for q in parts)
    parts.append((np.full(4, first - 1), np.full(4, (1 << 31) | (1 << 10) | 5, np.uint32)))  # an older frame's
    tail = aps(0, np.zeros((h, w), np.int64), last + 1, last + 1)
    parts.append((tail[0][:100], tail[1][:100]))  # a frame cut by the end of the recording
    tt = np.concatenate([q[0] for q in parts])
    aa = np.concatenate([q[1] for q in parts])
    k = np.argsort(tt, kind="stable")
    rec = np.zeros(tt.size, dtype=dt)
    rec["a"], rec["t"] = aa[k], tt[k]
    head = f"#!AER-DAT2.0\r\n# This is a raw AE data file\r\n# AEChip: {chip}\r\n".encode()
    path.write_bytes(head + rec.tobytes())


def test_aedat20_round_trip(tmp_path, capsys):
    ev = _events(2000, 240, 180, seed=3)
    f = tmp_path / "rec.aedat"
    write_aedat20(f, ev)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat", f, out, "--intrinsics", K_OPT) == 0
    text = capsys.readouterr().out
    assert (
        "4 APS reads outside a frame, 1 incomplete APS frames, 7 IMU samples, 1 third-cycle APS reads, "
        "1 special events not stored"
    ) in text
    s = read_scene(out)
    assert (s.camera.width, s.camera.height) == (240, 180)
    np.testing.assert_array_equal(s.events.x, ev[0])
    np.testing.assert_array_equal(s.events.y, ev[1])
    np.testing.assert_array_equal(s.events.t, ev[2])
    np.testing.assert_array_equal(s.events.p, np.where(ev[3] == 1, 1, -1))


def test_aedat20_events_only_summary(tmp_path, capsys):
    """A file of polarity events alone: the summary says "no APS frames" and prints no empty "not stored" note."""
    x, y, t, p = _events(500, 240, 180, seed=7)
    rec = np.zeros(t.size, dtype=[("a", ">u4"), ("t", ">i4")])
    rec["a"] = ((179 - y).astype(np.uint32) << 22) | ((239 - x).astype(np.uint32) << 12) | (p.astype(np.uint32) << 11)
    rec["t"] = t
    f = tmp_path / "ev.aedat"
    f.write_bytes(b"#!AER-DAT2.0\r\n# AEChip: eu.seebetter.ini.chips.davis.DAVIS240C\r\n" + rec.tobytes())
    out = tmp_path / "s.h5"
    assert run_ingest("aedat", f, out, "--intrinsics", K_OPT) == 0
    text = capsys.readouterr().out
    assert "DAVIS240C; no APS frames" in text
    assert "not stored" not in text
    assert not any(ln.strip() in ("note:", "note:  not stored") for ln in text.splitlines())
    np.testing.assert_array_equal(read_scene(out).events.t, t)


@pytest.mark.parametrize(
    "chip,w,h",
    [("eu.seebetter.ini.chips.davis.DAVIS240C", 240, 180), ("eu.seebetter.ini.chips.davis.Davis346B", 346, 260)],
)
def test_aedat20_aps_frames(tmp_path, chip, w, h):
    """APS frames rebuilt from reset/signal reads (known images and exposure windows) on DAVIS240 and DAVIS346;
    events in the same orientation as the frames (a DVS event and an APS read of one pixel carry mirrored x
    addresses in jAER's layout)."""
    ev = _events(3000, w, h, seed=4)
    rng = np.random.default_rng(9)
    starts = np.linspace(int(ev[2][0]) + 5000, int(ev[2][-1]) - 8000, 3).astype(np.int64)
    frames = [
        (int(s0), int(s0) + 2500 + 100 * i, rng.integers(0, 256, (h, w), dtype=np.uint8)) for i, s0 in enumerate(starts)
    ]
    frames[1][2][:, : w // 2] = 0  # left half dark: a mirrored frame would not match
    f = tmp_path / "rec.aedat"
    write_aedat20(f, ev, h=h, chip=chip, frames=frames, w=w)
    out = tmp_path / "s.h5"
    assert run_ingest("aedat", f, out, "--intrinsics", K_OPT, "--keep-events", "all") == 0
    s = read_scene(out)
    assert (s.camera.width, s.camera.height) == (w, h)
    np.testing.assert_array_equal(s.frames.blurry[..., 0], np.stack([fr[2] for fr in frames]))
    np.testing.assert_array_equal(s.frames.exposure_us, [[a, b] for a, b, _ in frames])
    np.testing.assert_array_equal(s.events.x, ev[0])
    np.testing.assert_array_equal(s.events.y, ev[1])
    np.testing.assert_array_equal(s.events.t, ev[2])


@pytest.mark.parametrize(
    "case,expected",
    [
        ("aedat4", "an AEDAT 4 file: use --format aedat4"),
        ("chip", "eigs decodes the jAER DAVIS layout of DAVIS240 and DAVIS346 (monochrome) only"),
        ("colour chip", "eigs decodes the jAER DAVIS layout of DAVIS240 and DAVIS346 (monochrome) only"),
        ("cut 2.0", "truncated: "),
        ("cut 3.1", "truncated: packet"),
        ("backwards", "timestamps go backwards at event"),
        ("not aedat", "not an AEDAT file"),
        ("corrupt header", "has a corrupted header"),
    ],
)
def test_errors(tmp_path, capsys, case, expected):
    f = tmp_path / "rec.aedat"
    ev = _events(700, 240, 180)
    if case == "aedat4":
        f.write_bytes(b"#!AER-DAT4.0\r\n")
    elif case == "chip":
        write_aedat20(f, ev, chip="ch.unizh.ini.jaer.chip.retina.DVS128")
    elif case == "colour chip":
        write_aedat20(f, ev, chip="eu.seebetter.ini.chips.davis.Davis346BColor")
    elif case == "cut 2.0":
        write_aedat20(f, ev)
        f.write_bytes(f.read_bytes()[:-3])
    elif case == "cut 3.1":
        write_aedat31(f, ev, [])
        f.write_bytes(f.read_bytes()[:-100])
    elif case == "backwards":
        t = ev[2].copy()
        t[400] = t[399] - 5
        write_aedat31(f, (ev[0], ev[1], t, ev[3]), [])
    elif case == "not aedat":
        f.write_bytes(b"hello world\n")
    elif case == "corrupt header":
        write_aedat31(f, ev, [])
        data = bytearray(f.read_bytes())
        start = data.index(b"#!END-HEADER\r\n") + len(b"#!END-HEADER\r\n")
        data[start + 4 : start + 8] = struct.pack("<i", -8)
        f.write_bytes(bytes(data))
    err = expect_failure(capsys, "aedat", f, tmp_path / "s.h5", "--intrinsics", K_OPT)
    assert expected in err, err
    assert err.startswith(f"eigs ingest: error: {f}: "), err
