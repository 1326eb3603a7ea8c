"""jAER / cAER recordings (``--format aedat``): AEDAT 3.1 (polarity events and APS frames) and AEDAT 2.0 (DAVIS240
polarity events). AEDAT 4 files are ``--format aedat4``.

**AEDAT 3.1** (cAER / libcaer; inivation.gitlab.io "AEDAT 3.1"): ``#`` header lines up to ``#!END-HEADER``, then
packets. Each packet has a 28-byte little-endian header (int16 eventType, int16 eventSource, int32 eventSize,
int32 eventTSOffset, int32 eventTSOverflow, int32 eventCapacity, int32 eventNumber, int32 eventValid) and
eventNumber events of eventSize bytes. Timestamps are int32 µs; the full time is ``eventTSOverflow << 31 | ts``.
- type 1, polarity (8 bytes): uint32 data (bit 0 valid, bit 1 polarity ON, bits 16–2 y, bits 31–17 x), int32 t.
  (0, 0) is the top-left pixel (libcaer's convention): no flip.
- type 2, frame: int32 info (bit 0 valid, bits 3–1 channels), ts start/end of frame, ts start/end of exposure,
  lengthX, lengthY, positionX, positionY, then uint16 pixels (row-major from the top-left, channels interleaved,
  10-bit ADC values left-aligned to 16 bits): stored as ``value >> 8``. Exposure = [start, end of exposure).
  Region-of-interest frames (position ≠ 0 or size ≠ the sensor) are refused.
- other types (special, IMU, …) and events whose valid bit is 0 are counted, not stored.

**AEDAT 2.0** (jAER) from DAVIS240 (240×180) and DAVIS346 (346×260) chips: ``#`` header lines (``#!AER-DAT2.0``,
``# AEChip: …``), then big-endian records of uint32 address + int32 timestamp (µs). The address layout is jAER's
``eu.seebetter.ini.chips.DavisChip`` constants, decoded by ``DavisBaseCamera.DavisEventExtractor`` for every DAVIS
camera class of both sizes (``Davis346BaseCamera`` restates the same shifts and has no extractor of its own):
y = bits 30–22, x = bits 21–12, bit 31 = 0 for DVS, 1 for APS/IMU.
- DVS (bit 31 = 0): bit 10 set = external input (counted, not stored); else polarity = bit 11 (1 = ON). jAER
  mirrors the DVS column (``e.x = sizeX − 1 − x``) and counts rows from the bottom: column = W − 1 − x,
  row = H − 1 − y.
- IMU (``address & 0x80000C00 == 0x80000C00``): counted, not stored.
- APS (bit 31 = 1): bits 11–10 = readout cycle (0 reset read, 1 signal read; 2, the deprecated "C" read:
  counted as a third-cycle read, ignored), bits 9–0 = 10-bit ADC sample. APS columns are not mirrored (jAER keeps
  ``e.x = x``): column = x, row = H − 1 − y. A frame is a run of reset reads followed by a run of signal
  reads, complete when every pixel has one of each (as jAER 3.0's ``DavisFrameAssembler``: completion by count,
  not by the first/last pixel address, which differs between camera variants); pixel = reset − signal (correlated
  double sampling, clamped at 0, 10 bits) → 8 bits as ``value >> 2``. Incomplete frames (cut at the file's start
  or end, lost samples, rolling-shutter readout whose reset and signal reads interleave) are counted, not stored.
- Exposure of an APS frame: jAER's global-shutter definition (``DavisBaseCamera``: start of exposure at the
  **last reset read**, end at the **first signal read**): ``[t(last reset read), t(first signal read))``; a frame
  whose window is empty is counted and not stored.
Colour DAVIS chips (``…Color`` classes: a colour-filter extractor), DAVIS640/208/128 and DVS128 are refused.

Timestamps are kept as recorded (µs from the camera's reset); going backwards is an error naming the event.
Sensor size: from the chip named in the header (DAVIS240: 240×180; DAVIS346: 346×260; DVS128: 128×128), the
frames, or ``--sensor-size``. No calibration is stored: give ``--intrinsics``.
"""

from __future__ import annotations

import logging
import re
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.chunks import Rebatcher, TimeOrder
from eigs.ingest.options import IngestOptions
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import to_pixel

log = logging.getLogger(__name__)

CHUNK_EVENTS = 1 << 22
PACKET_HEADER = struct.Struct("<hhiiiiii")
CHIP_SIZES = {"DAVIS240": (240, 180), "DAVIS346": (346, 260), "DVS128": (128, 128), "DAVIS640": (640, 480)}
DAVIS20_CHIPS = ("DAVIS240", "DAVIS346")  # chips whose AEDAT 2.0 layout eigs decodes (jAER DavisChip)
APS_BIT = np.uint32(1 << 31)
IMU_CODE = np.uint32(0x80000C00)
MAX_HEADER = 1 << 20


@dataclass
class Header:
    version: str  # "2.0" or "3.1"
    data_start: int
    chip: str | None
    chip_line: str = ""  # the header line naming the chip (e.g. "AEChip: eu.seebetter.ini.chips.davis.DAVIS240C")
    width: int | None = None
    height: int | None = None
    lines: list[str] = field(default_factory=list)


def read_header(path: Path) -> Header:
    lines: list[str] = []
    pos = 0
    with open(path, "rb") as fh:
        first = fh.readline(200)
        m = re.match(rb"#!AER-DAT(\d\.\d)", first)
        if not m:
            raise EigsError(path, f"not an AEDAT file (starts with {first[:16]!r}, expected '#!AER-DAT2.0' or 3.1)")
        version = m.group(1).decode()
        if version.startswith("4"):
            raise EigsError(path, "an AEDAT 4 file: use --format aedat4")
        if version not in ("2.0", "3.1"):
            raise EigsError(path, f"AEDAT {version}; eigs reads 2.0 and 3.1 (and 4 with --format aedat4)")
        pos = len(first)
        while True:
            peek = fh.read(1)
            if peek != b"#":
                break
            line = fh.readline(MAX_HEADER)
            if not line.endswith(b"\n"):
                raise EigsError(path, "truncated header (a '#' line without its end)")
            pos += 1 + len(line)
            text = line.decode("latin-1").strip()
            lines.append(text)
            if text.startswith("!END-HEADER"):
                break
            if pos > MAX_HEADER:
                raise EigsError(path, "header longer than 1 MiB")
    chip, chip_line = None, ""
    for ln in lines:
        mm = re.search(r"(DAVIS\d+|DVS128)", ln, re.IGNORECASE)
        if mm and ("chip" in ln.lower() or "source" in ln.lower()):
            chip, chip_line = mm.group(1).upper(), ln
            break
    h = Header(version, pos, chip, chip_line, lines=lines)
    if chip is not None:
        for key, (w, hh) in CHIP_SIZES.items():
            if chip.startswith(key):
                h.width, h.height = w, hh
    return h


# ---------------------------------------------------------------------------------------------------- AEDAT 3.1
@dataclass
class _Frame:
    offset: int  # byte offset of the frame event
    exposure: tuple[int, int]
    size: tuple[int, int]
    channels: int


def _packets(path: Path, start: int) -> Iterator[tuple[int, tuple, int]]:
    """(byte offset of the events, header fields, packet index) of each AEDAT 3.1 packet; checks sizes."""
    size = path.stat().st_size
    pos, k = start, 0
    with open(path, "rb") as fh:
        fh.seek(pos)
        while pos < size:
            raw = fh.read(PACKET_HEADER.size)
            if len(raw) < PACKET_HEADER.size:
                raise EigsError(path, f"truncated: packet {k} header cut at byte {pos}")
            hdr = PACKET_HEADER.unpack(raw)
            etype, _src, esize, _tsoff, _ovf, cap, num, _valid = hdr
            if esize <= 0 or cap < 0 or num < 0 or num > cap:
                raise EigsError(path, f"packet {k} at byte {pos} has a corrupted header {hdr}")
            end = pos + PACKET_HEADER.size + cap * esize
            if end > size:
                raise EigsError(path, f"truncated: packet {k} at byte {pos} needs {cap * esize} bytes, the file ends")
            yield pos + PACKET_HEADER.size, hdr, k
            pos = end
            fh.seek(pos)
            k += 1


def _scan31(path: Path, h: Header) -> tuple[list[_Frame], int, dict[int, int]]:
    """First pass: frame metadata, polarity event count, counts of other packet types."""
    frames: list[_Frame] = []
    n_pol = 0
    other: dict[int, int] = {}
    with open(path, "rb") as fh:
        for off, hdr, k in _packets(path, h.data_start):
            etype, _, esize, _, ovf, _, num, _ = hdr
            if etype == 1:
                if esize != 8:
                    raise EigsError(path, f"polarity packet {k} has {esize}-byte events, expected 8")
                n_pol += num
            elif etype == 2:
                if esize < 36:
                    raise EigsError(path, f"frame packet {k} has {esize}-byte events, too small")
                fh.seek(off)
                for j in range(num):
                    fh.seek(off + j * esize)
                    info, _sf, _ef, se, ee, lx, ly, px, py = struct.unpack("<9i", fh.read(36))
                    if not info & 1:
                        continue
                    ch = (info >> 1) & 7
                    if ch not in (1, 3) or lx <= 0 or ly <= 0 or 36 + 2 * lx * ly * ch > esize:
                        raise EigsError(path, f"frame {len(frames)} (packet {k}) has a corrupted header")
                    if px or py:
                        raise EigsError(path, f"frame {len(frames)} is a region of interest at ({px}, {py})")
                    base = ovf << 31
                    if ee < se:
                        raise EigsError(path, f"frame {len(frames)} exposure ends before it starts")
                    frames.append(_Frame(off + j * esize, (base | se, base | ee), (lx, ly), ch))
            else:
                other[etype] = other.get(etype, 0) + num
    return frames, n_pol, other


def _events31(path: Path, h: Header, width: int, height: int, chunk: int = CHUNK_EVENTS) -> Iterator[EventChunk]:
    where = str(path)
    order = TimeOrder(path)
    batch = Rebatcher(chunk)
    offset = 0
    with open(path, "rb") as fh:
        for off, hdr, _k in _packets(path, h.data_start):
            if hdr[0] != 1 or hdr[6] == 0:
                continue
            fh.seek(off)
            rec = np.frombuffer(fh.read(8 * hdr[6]), dtype=[("d", "<u4"), ("t", "<i4")])
            rec = rec[(rec["d"] & 1).astype(bool)]
            if rec.size == 0:
                continue
            if np.any(rec["t"] < 0):
                raise EigsError(path, f"negative timestamp in the packet at byte {off}: corrupted file")
            t = (np.int64(hdr[4]) << 31) | rec["t"].astype(np.int64)
            order(t, offset)
            d = rec["d"]
            x = to_pixel((d >> 17).astype(np.int64), width, "x", where, offset)
            y = to_pixel(((d >> 2) & 0x7FFF).astype(np.int64), height, "y", where, offset)
            p = np.where(d & 2, np.int8(1), np.int8(-1))
            offset += t.size
            yield from batch.add((x, y, t, p))
    yield from batch.rest()


# ---------------------------------------------------------------------------------------------------- AEDAT 2.0
def _records20(path: Path, h: Header, chunk: int) -> Iterator[np.ndarray]:
    """The AEDAT 2.0 records from the data start, ``chunk`` at a time: structured arrays of ``a`` (address,
    big-endian uint32) and ``t`` (timestamp µs, big-endian int32)."""
    with open(path, "rb") as fh:
        fh.seek(h.data_start)
        while True:
            buf = fh.read(8 * chunk)
            if not buf:
                return
            yield np.frombuffer(buf, dtype=[("a", ">u4"), ("t", ">i4")])


def _events20(path: Path, h: Header, width: int, height: int, counts: dict[str, int], chunk: int = CHUNK_EVENTS):
    where = str(path)
    order = TimeOrder(path)
    offset = 0
    size = path.stat().st_size - h.data_start
    if size % 8:
        raise EigsError(path, f"truncated: {size} bytes of records is not a multiple of 8 (cut file)")
    for rec in _records20(path, h, chunk):
        a = rec["a"]
        aps = (a >> 31).astype(bool)
        special = ~aps & ((a >> 10) & 1).astype(bool)
        imu = (a & IMU_CODE) == IMU_CODE
        counts["IMU samples"] = counts.get("IMU samples", 0) + int(np.count_nonzero(imu))
        third = aps & ~imu & (((a >> 10) & 3) == 2)
        counts["third-cycle APS reads"] = counts.get("third-cycle APS reads", 0) + int(np.count_nonzero(third))
        counts["special events"] = counts.get("special events", 0) + int(np.count_nonzero(special))
        dvs = ~aps & ~special
        a, t32 = a[dvs], rec["t"][dvs]
        if np.any(t32 < 0):
            raise EigsError(path, f"negative timestamp near event {offset}: corrupted file")
        t = t32.astype(np.int64)
        order(t, offset)
        xr = ((a >> 12) & 0x3FF).astype(np.int64)
        yr = ((a >> 22) & 0x1FF).astype(np.int64)
        x = (width - 1) - to_pixel(xr, width, "x address", where, offset).astype(np.int64)
        y = (height - 1) - to_pixel(yr, height, "y address", where, offset).astype(np.int64)
        x, y = x.astype(np.uint16), y.astype(np.uint16)
        p = np.where((a >> 11) & 1, np.int8(1), np.int8(-1))
        offset += t.size
        yield x, y, t, p


@dataclass
class _ApsFrame:
    """A complete AEDAT 2.0 APS frame: the records [first, stop) hold its reset and signal reads."""

    first: int  # record index of its first reset read
    stop: int  # record index past its last signal read
    exposure: tuple[int, int]  # [last reset read, first signal read) µs


@dataclass
class _ApsState:
    """The frame being assembled while scanning (reset phase, then signal phase)."""

    n: int  # pixels per frame
    phase: int = -1  # -1 none, 0 reset reads, 1 signal reads
    first: int = 0
    reset_seen: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    signal_seen: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    bad: bool = False
    last_reset_t: int = 0
    first_signal_t: int = 0
    signals: int = 0

    def start(self, first: int) -> None:
        self.phase, self.first, self.bad, self.signals = 0, first, False, 0
        self.reset_seen = np.zeros(self.n, np.int32)
        self.signal_seen = np.zeros(self.n, np.int32)


def _aps_fields(rec: np.ndarray, width: int, height: int) -> tuple[np.ndarray, ...]:
    """APS reset/signal reads among AEDAT 2.0 records → (positions in ``rec``, cycle 0/1, pixel index
    row * W + column with -1 outside the sensor, 10-bit sample, timestamp); the other APS cycles are dropped."""
    a = rec["a"]
    aps = ((a & APS_BIT) != 0) & ((a & IMU_CODE) != IMU_CODE)
    cyc = (a >> 10) & 3
    pos = np.flatnonzero(aps & (cyc <= 1))
    a = a[pos]
    xr = ((a >> 12) & 0x3FF).astype(np.int64)
    yr = ((a >> 22) & 0x1FF).astype(np.int64)
    inside = (xr < width) & (yr < height)
    idx = np.where(inside, (height - 1 - yr) * width + xr, -1)
    return pos, cyc[pos].astype(np.int8), idx, (a & 0x3FF).astype(np.int32), rec["t"][pos].astype(np.int64)


def _scan_aps20(path: Path, h: Header, width: int, height: int, counts: dict[str, int], chunk: int = CHUNK_EVENTS):
    """First pass over an AEDAT 2.0 file: the complete APS frames (record ranges and exposure windows).

    Reads ``chunk`` records at a time; the reset/signal runs are applied to per-pixel counters with NumPy, so a frame
    is complete when each of its W·H pixels has exactly one reset and one signal read."""
    size = path.stat().st_size - h.data_start
    if size % 8:
        raise EigsError(path, f"truncated: {size} bytes of records is not a multiple of 8 (cut file)")
    frames: list[_ApsFrame] = []
    st = _ApsState(width * height)
    base = 0

    def close(stop: int) -> None:
        ok = (
            not st.bad
            and st.signals == st.n
            and bool(np.all(st.reset_seen == 1))
            and bool(np.all(st.signal_seen == 1))
            and st.first_signal_t > st.last_reset_t
        )
        if ok:
            frames.append(_ApsFrame(st.first, stop, (st.last_reset_t, st.first_signal_t)))
        else:
            counts["incomplete APS frames"] = counts.get("incomplete APS frames", 0) + 1
        st.phase = -1

    for rec in _records20(path, h, chunk):
        pos, cyc, idx, _, t = _aps_fields(rec, width, height)
        if pos.size == 0:
            base += rec.size
            continue
        if np.any(t < 0):
            k = base + int(pos[np.flatnonzero(t < 0)[0]])
            raise EigsError(path, f"negative timestamp in the APS sample at record {k}: corrupted file")
        cuts = np.flatnonzero(np.diff(cyc)) + 1
        for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, pos.size], strict=True):
            c, run = int(cyc[lo]), idx[lo:hi]
            if c == 0:
                if st.phase == 1:
                    close(base + int(pos[lo]))
                if st.phase == -1:
                    st.start(base + int(pos[lo]))
                seen = st.reset_seen
                st.last_reset_t = int(t[hi - 1])
            else:
                if st.phase == -1:  # signal reads of a frame whose resets precede the file (or were lost)
                    counts["APS reads outside a frame"] = counts.get("APS reads outside a frame", 0) + hi - lo
                    continue
                if st.phase == 0:
                    st.phase, st.first_signal_t = 1, int(t[lo])
                seen = st.signal_seen
                st.signals += hi - lo
            st.bad |= bool(np.any(run < 0))
            ok = run[run >= 0]
            seen += np.bincount(ok, minlength=st.n).astype(np.int32)
            if c == 1 and st.signals >= st.n:
                close(base + int(pos[hi - 1]) + 1)
        base += rec.size
    if st.phase != -1:
        counts["incomplete APS frames"] = counts.get("incomplete APS frames", 0) + 1
    return frames


def _load_aps20(path: Path, h: Header, frames: list[_ApsFrame], idx: np.ndarray, width: int, height: int):
    """(M, H, W, 1) uint8 frames ``idx``: reset − signal per pixel (clamped at 0, 10 bits) >> 2."""
    out = np.empty((len(idx), height, width, 1), np.uint8)
    n = width * height
    with open(path, "rb") as fh:
        for j, i in enumerate(idx):
            f = frames[int(i)]
            fh.seek(h.data_start + 8 * f.first)
            rec = np.frombuffer(fh.read(8 * (f.stop - f.first)), dtype=[("a", ">u4"), ("t", ">i4")])
            _, cyc, pix, val, _ = _aps_fields(rec, width, height)
            reset = np.zeros(n, np.int32)
            signal = np.zeros(n, np.int32)
            r, sg = cyc == 0, cyc == 1
            if np.count_nonzero(r) != n or np.count_nonzero(sg) != n or np.any(pix < 0):
                raise EigsError(path, f"APS frame {int(i)} changed between reads (the file changed while reading)")
            reset[pix[r]] = val[r]
            signal[pix[sg]] = val[sg]
            cds = np.clip(reset - signal, 0, 1023)
            out[j, ..., 0] = (cds >> 2).astype(np.uint8).reshape(height, width)
    return out


def open_aedat_legacy_source(source: str, opts: IngestOptions) -> RawSource:
    """Open an AEDAT 2.0 or 3.1 file as a :class:`RawSource`."""
    from eigs.ingest.poses import read_groundtruth

    opts.refuse("aedat", "time_unit", "frames")
    path = Path(source)
    if not path.is_file():
        raise EigsError(path, "no such file")
    h = read_header(path)
    src = RawSource(path=path, fmt="aedat", name=path.stem, width=h.width, height=h.height)
    if opts.groundtruth is not None:
        src.trajectory = read_groundtruth(Path(opts.groundtruth))
    if h.version == "2.0":
        if h.chip is None or not h.chip.startswith(DAVIS20_CHIPS) or "color" in h.chip_line.lower():
            raise EigsError(
                path,
                f"AEDAT 2.0 from chip {h.chip_line or 'unknown'}: eigs decodes the jAER DAVIS layout of DAVIS240 and "
                "DAVIS346 (monochrome) only",
            )
        assert h.width is not None and h.height is not None
        w20, h20 = h.width, h.height
        counts: dict[str, int] = {}
        aps = _scan_aps20(path, h, w20, h20, counts)
        frames_note = (
            f"{len(aps)} APS frames (reset − signal, exposure from the last reset read to the first signal read)"
            if aps
            else "no APS frames"
        )
        src.notes.append(f"AEDAT 2.0, chip {h.chip_line.split(':')[-1].strip()}; {frames_note}")
        if aps:
            exp = np.asarray([f.exposure for f in aps], dtype=np.int64)
            back = np.flatnonzero(np.diff(exp[:, 0]) < 0)
            if back.size:
                raise EigsError(path, f"APS frame exposures go backwards at frame {int(back[0]) + 1}")
            src.n_frames = len(aps)
            src.exposure_us = exp
            src.load_frames = lambda idx: _load_aps20(path, h, aps, idx, w20, h20)

        def events20(w: int, hh: int) -> Iterator[EventChunk]:
            yield from _events20(path, h, w, hh, counts)
            skipped = [f"{n} {k}" for k, n in counts.items() if n]
            if skipped:
                src.notes.append(", ".join(skipped) + " not stored")

        src.events = events20
        return src
    frames, n_pol, other = _scan31(path, h)
    src.notes.append(
        f"AEDAT 3.1, source {h.chip or 'unknown'}; {len(frames)} frames; "
        + (", ".join(f"{n} events of type {t}" for t, n in sorted(other.items())) or "no other events")
        + " not stored"
    )
    if frames:
        sizes = {f.size for f in frames}
        chans = {f.channels for f in frames}
        if len(sizes) > 1 or len(chans) > 1:
            raise EigsError(path, f"frames differ in size or channels: {sorted(sizes)}, {sorted(chans)}")
        fw, fhh = sizes.pop()
        if h.width is not None and (fw, fhh) != (h.width, h.height):
            raise EigsError(path, f"frames are {fw}×{fhh} but the chip {h.chip} is {h.width}×{h.height}")
        src.width, src.height = fw, fhh
        exp = np.asarray([f.exposure for f in frames], dtype=np.int64)
        back = np.flatnonzero(np.diff(exp[:, 0]) < 0)
        if back.size:
            raise EigsError(path, f"frame exposures go backwards at frame {int(back[0]) + 1}")
        src.n_frames = len(frames)
        src.exposure_us = exp
        ch = chans.pop()

        def load(idx: np.ndarray) -> np.ndarray:
            out = np.empty((len(idx), fhh, fw, ch), np.uint8)
            with open(path, "rb") as fh:
                for j, i in enumerate(idx):
                    fh.seek(frames[int(i)].offset + 36)
                    px = np.frombuffer(fh.read(2 * fw * fhh * ch), dtype="<u2")
                    out[j] = (px >> 8).astype(np.uint8).reshape(fhh, fw, ch)
            return out

        src.load_frames = load
    if n_pol:
        src.n_events = n_pol
        src.events = lambda w, hh: _events31(path, h, w, hh)
    return src
