"""Prophesee recordings (``--format prophesee``): RAW files in EVT 2.0, EVT 2.1 or EVT 3.0, and DAT files.

Decoded here in NumPy (vectorised, :data:`CHUNK_WORDS` words at a time: 4 MiB of EVT 2.0, 1 MiB of EVT 3.0),
following Prophesee's published format specifications (docs.prophesee.ai, "EVT 2.0 Format", "EVT 2.1 Format",
"EVT 3.0 Format", "DAT File Format").
No maintained PyPI decoder streams all four in bounded memory (``docs/ingestion.md`` says why).

- **Header**: lines starting with ``%`` (up to ``% end`` when present). RAW: ``% format EVT3;height=720;width=1280``
  (or ``EVT2``, ``EVT21``), or the older ``% evt 3.0`` + ``% geometry 1280x720``. DAT: ``% Height``,
  ``% Width``, ``% Version 2``, then one byte event type and one byte event size (8). A ``% t0 <µs>`` line (faery
  writes one by default and stores times relative to it) is the time origin: added to every timestamp.
- **EVT 2.0** (32-bit little-endian words; type = bits 31–28): CD_OFF 0x0 / CD_ON 0x1 with timestamp LSB
  (bits 27–22), x (21–11), y (10–0); EVT_TIME_HIGH 0x8 with bits 27–0 = timestamp >> 6; EXT_TRIGGER 0xA,
  OTHERS 0xE, CONTINUED 0xF (counted, not stored). t = TIME_HIGH << 6 | LSB (34 bits, µs).
- **EVT 2.1** (64-bit little-endian words; type = bits 63–60): EVT_NEG 0x0 / EVT_POS 0x1 with timestamp LSB
  (59–54), x (53–43, a multiple of 32), y (42–32) and a 32-bit validity mask (31–0): bit i = an event at x + i;
  EVT_TIME_HIGH 0x8 with bits 59–32 = timestamp >> 6; 0xA, 0xE, 0xF as above.
- **EVT 3.0** (16-bit little-endian words; type = bits 15–12): EVT_ADDR_Y 0x0 (y = bits 10–0), EVT_ADDR_X 0x2
  (polarity bit 11, x bits 10–0: one event), VECT_BASE_X 0x3 (polarity, base x), VECT_12 0x4 / VECT_8 0x5
  (validity masks of 12 / 8 pixels from the base x, which then advances by 12 / 8), EVT_TIME_LOW 0x6 and
  EVT_TIME_HIGH 0x8 (12 bits each: t = TIME_HIGH << 12 | TIME_LOW; a TIME_HIGH resets TIME_LOW to 0),
  CONTINUED_4 0x7, EXT_TRIGGER 0xA, OTHERS 0xE, CONTINUED_12 0xF (counted or skipped).
- **DAT** (after the header): 8-byte records, uint32 timestamp µs, uint32 with x (bits 13–0), y (27–14) and
  polarity (31–28: 0 = OFF, 1 = ON).

Time: µs, kept on the sensor clock (from the camera's start). The timestamp high part wraps (EVT 2.x: 2³⁴ µs ≈
4.8 h; EVT 3.0: 2²⁴ µs ≈ 16.8 s): a TIME_HIGH that drops by more than half its range is a wrap (+1 period);
any smaller drop, or events that go backwards, is an error naming the byte offset / event. CD events before the
first TIME_HIGH have no time and are dropped and counted (as Metavision does). A word of an undefined type,
an EVT 3.0 event before any EVT_ADDR_Y, a polarity other than 0/1 (DAT) or a file cut inside a word is an error.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.chunks import TimeOrder
from eigs.ingest.options import IngestOptions
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import to_pixel

log = logging.getLogger(__name__)

CHUNK_WORDS = {"evt2": 1 << 20, "evt21": 1 << 18, "evt3": 1 << 19, "dat": 1 << 20}  # words per decoding step
MAX_HEADER = 1 << 20
ENCODINGS = {"evt2": "EVT 2.0", "evt21": "EVT 2.1", "evt3": "EVT 3.0", "dat": "DAT"}
WORD_BYTES = {"evt2": 4, "evt21": 8, "evt3": 2, "dat": 8}
EventChunkRaw = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # x, y, t µs, p {0, 1}: int64 each


@dataclass
class Header:
    """What the text header says: encoding (a key of :data:`ENCODINGS`), sensor size, byte offset of the data."""

    encoding: str
    width: int | None
    height: int | None
    data_start: int
    lines: list[str] = field(default_factory=list)
    t0_us: int = 0  # the ``% t0`` line's time origin (µs), added to every stored timestamp


def _header_lines(path: Path) -> tuple[list[str], int]:
    """The ``%`` header lines (text) and the byte offset right after them."""
    lines: list[str] = []
    with open(path, "rb") as fh:
        pos = 0
        while True:
            first = fh.read(1)
            if first != b"%":
                break
            line = fh.readline(MAX_HEADER)
            if not line.endswith(b"\n"):
                raise EigsError(path, "truncated header (a '%' line without its end)")
            pos += 1 + len(line)
            if pos > MAX_HEADER:
                raise EigsError(path, f"header longer than {MAX_HEADER} bytes (not a Prophesee file?)")
            text = line.decode("latin-1").strip()
            lines.append(text)
            if text.lower() == "end":
                break
    return lines, pos


def read_header(path: Path) -> Header:
    """Parse the header of a RAW or DAT file (the extension decides which); EigsError when it says too little."""
    lines, pos = _header_lines(path)
    kv: dict[str, str] = {}
    for ln in lines:
        parts = ln.split(None, 1)
        if parts:
            kv[parts[0].lower()] = parts[1].strip() if len(parts) > 1 else ""
    width = height = None
    t0 = _time_origin(path, kv.get("t0"))
    if path.suffix.lower() == ".dat":
        version = kv.get("version")
        if version is None or version.strip() != "2":
            raise EigsError(path, f"DAT version {version!r}; eigs reads version 2 (the '% Version 2' header line)")
        try:
            if "width" in kv and "height" in kv:
                width, height = int(kv["width"]), int(kv["height"])
        except ValueError:
            raise EigsError(path, f"header Width/Height are not integers: {kv['width']!r}, {kv['height']!r}") from None
        with open(path, "rb") as fh:
            fh.seek(pos)
            two = fh.read(2)
        if len(two) < 2:
            raise EigsError(path, "truncated: the header is not followed by the event type and size bytes")
        ev_type, ev_size = two[0], two[1]
        if ev_type not in (0x00, 0x0C) or ev_size != 8:
            raise EigsError(path, f"event type 0x{ev_type:02x} of {ev_size} bytes; eigs reads CD events (8 bytes)")
        return Header("dat", width, height, pos + 2, lines, t0)

    enc = None
    fmt = kv.get("format")
    if fmt is not None:
        fields = fmt.split(";")
        name = fields[0].strip().upper()
        enc = {"EVT2": "evt2", "EVT21": "evt21", "EVT3": "evt3"}.get(name)
        if enc is None:
            raise EigsError(path, f"header format {fields[0]!r}; eigs reads EVT2, EVT21 and EVT3")
        opts = dict(f.split("=", 1) for f in fields[1:] if "=" in f)
        try:
            if "width" in opts and "height" in opts:
                width, height = int(opts["width"]), int(opts["height"])
        except ValueError:
            raise EigsError(path, f"header format {fmt!r} has a non-integer width or height") from None
    if "evt" in kv:
        old = {"2.0": "evt2", "2.1": "evt21", "3.0": "evt3"}.get(kv["evt"].strip())
        if old is None:
            raise EigsError(path, f"header says evt {kv['evt']!r}; eigs reads 2.0, 2.1 and 3.0")
        if enc is not None and enc != old:
            raise EigsError(path, f"header format {fmt!r} contradicts 'evt {kv['evt']}'")
        enc = old
    if enc is None:
        raise EigsError(
            path, "the header names no event encoding ('% format EVT3;…' or '% evt 3.0'); not a Prophesee RAW file?"
        )
    if "geometry" in kv:
        m = re.fullmatch(r"\s*(\d+)\s*x\s*(\d+)\s*", kv["geometry"])
        if not m:
            raise EigsError(path, f"header geometry {kv['geometry']!r} is not WIDTHxHEIGHT")
        gw, gh = int(m.group(1)), int(m.group(2))
        if width is not None and (gw, gh) != (width, height):
            raise EigsError(path, f"header geometry {gw}x{gh} contradicts the format line's {width}x{height}")
        width, height = gw, gh
    return Header(enc, width, height, pos, lines, t0)


def _time_origin(path: Path, value: str | None) -> int:
    """The ``% t0 <µs>`` header line (faery writes it, ``T0`` or ``t0``, and stores times relative to it): a whole
    number of µs ≥ 0, 0 without the line; anything else is an EigsError (never a silent shift)."""
    if value is None:
        return 0
    text = value.strip()
    if not text.isdigit():
        raise EigsError(path, f"header t0 {value!r} is not a whole number of µs (the '% t0 <µs>' time origin)")
    return int(text)


# ------------------------------------------------------------------------------------------------ decoding state
@dataclass
class _State:
    """Decoder state carried from one chunk to the next."""

    time_high: int | None = None  # last TIME_HIGH payload (raw, before wrap correction)
    loops: int = 0  # wraps of the TIME_HIGH counter
    time_low: int = 0  # EVT 3.0: current TIME_LOW (reset by TIME_HIGH)
    y: int | None = None  # EVT 3.0: current row
    x_next: int | None = None  # EVT 3.0: x of the next vector word's first pixel
    vect_pol: int = 0  # EVT 3.0: polarity of the current vector base
    dropped: int = 0  # CD events before the first TIME_HIGH
    triggers: int = 0  # EXT_TRIGGER words
    others: int = 0  # OTHERS / CONTINUED words


def _ffill(mask: np.ndarray) -> np.ndarray:
    """(n,) bool → (n,) int64 index of the last True at or before each position, −1 before the first."""
    idx = np.where(mask, np.arange(mask.size, dtype=np.int64), np.int64(-1))
    return np.maximum.accumulate(idx) if idx.size else idx


def _time_high(path: Path, values: np.ndarray, positions: np.ndarray, st: _State, bits: int, unit: int) -> np.ndarray:
    """Unwrapped TIME_HIGH values (int64) of one chunk; updates ``st``. ``positions``: byte offsets (messages)."""
    if values.size == 0:
        return values.astype(np.int64)
    v = values.astype(np.int64)
    prev = np.concatenate([[st.time_high if st.time_high is not None else v[0]], v])
    d = np.diff(prev)
    half = 1 << (bits - 1)
    wrap = d < -half
    back = (d < 0) & ~wrap
    if np.any(back):
        i = int(np.flatnonzero(back)[0])
        raise EigsError(
            path,
            f"EVT_TIME_HIGH goes backwards at byte {int(positions[i])} ({int(prev[i]) * unit} → {int(v[i]) * unit} µs "
            "in the counter's range): corrupted file",
        )
    loops = st.loops + np.cumsum(wrap)
    st.time_high, st.loops = int(v[-1]), int(loops[-1])
    return v + (loops << bits)


def _decode_evt3(path: Path, w: np.ndarray, base: int, st: _State) -> EventChunkRaw:
    """EVT 3.0 words (n,) uint16 → raw events (x, y, t, p) in word order; ``base``: byte offset of w[0]."""
    typ = (w >> 12).astype(np.uint8)
    pay = (w & 0x0FFF).astype(np.int64)
    bad = ~np.isin(typ, (0x0, 0x2, 0x3, 0x4, 0x5, 0x6, 0x7, 0x8, 0xA, 0xE, 0xF))
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise EigsError(path, f"undefined EVT 3.0 word type 0x{typ[i]:x} at byte {base + 2 * i}: corrupted file")
    n = w.size
    st.triggers += int(np.count_nonzero(typ == 0xA))
    st.others += int(np.count_nonzero(typ == 0xE))

    # time: TIME_HIGH (unwrapped, 12 bits) << 12 + TIME_LOW, TIME_LOW reset by each TIME_HIGH
    is_th, is_tl = typ == 0x8, typ == 0x6
    th_pos = np.flatnonzero(is_th)
    carried_high = None if st.time_high is None else (st.time_high + (st.loops << 12))
    th = _time_high(path, pay[th_pos], base + 2 * th_pos, st, 12, 4096)
    th_full = np.zeros(n, np.int64)
    th_full[th_pos] = th
    ih, il = _ffill(is_th), _ffill(is_tl)
    have_time = (ih >= 0) | (carried_high is not None)
    high = np.where(ih >= 0, th_full[np.maximum(ih, 0)], carried_high if carried_high is not None else 0)
    low = np.where(il > ih, pay[np.maximum(il, 0)], np.where(ih >= 0, 0, st.time_low))
    t_word = (high << 12) + low
    if il[-1] > ih[-1]:
        st.time_low = int(pay[il[-1]])
    elif ih[-1] >= 0:
        st.time_low = 0

    # row
    iy = _ffill(typ == 0x0)
    y_word = np.where(iy >= 0, pay[np.maximum(iy, 0)] & 0x7FF, st.y if st.y is not None else -1)
    if iy[-1] >= 0:
        st.y = int(pay[iy[-1]] & 0x7FF)

    # vectors: x of each vector word's first pixel = base x + 12/8 per vector word since that base
    is_vb = typ == 0x3
    inc = np.where(typ == 0x4, 12, np.where(typ == 0x5, 8, 0)).astype(np.int64)
    cum = np.cumsum(inc)
    ib = _ffill(is_vb)
    ibc = np.maximum(ib, 0)
    vb_x = pay[ibc] & 0x7FF
    since = cum - inc - np.where(ib >= 0, cum[ibc], 0)  # increments of the vector words after the base, before i
    x_start = np.where(ib >= 0, vb_x + since, (st.x_next if st.x_next is not None else -(1 << 40)) + since)
    vpol = np.where(ib >= 0, (pay[ibc] >> 11) & 1, st.vect_pol)
    if ib[-1] >= 0:
        st.x_next = int((pay[ib[-1]] & 0x7FF) + cum[-1] - cum[ib[-1]])
        st.vect_pol = int((pay[ib[-1]] >> 11) & 1)
    elif st.x_next is not None:
        st.x_next += int(cum[-1])

    single = np.flatnonzero(typ == 0x2)
    vect = np.flatnonzero((typ == 0x4) | (typ == 0x5))
    masks = pay[vect] & np.where(typ[vect] == 0x5, 0xFF, 0xFFF)
    bits = ((masks[:, None] >> np.arange(12, dtype=np.int64)[None, :]) & 1).astype(bool)
    vrow, vcol = np.nonzero(bits)
    vword = vect[vrow]
    words = np.concatenate([single, vword])
    order = np.argsort(np.concatenate([single * 16, vword * 16 + vcol]), kind="stable")
    words = words[order]
    x = np.concatenate([pay[single] & 0x7FF, x_start[vword] + vcol])[order]
    p = np.concatenate([(pay[single] >> 11) & 1, vpol[vword]])[order]
    ev_ok = have_time[words]
    st.dropped += int(np.count_nonzero(~ev_ok))
    words, x, p = words[ev_ok], x[ev_ok], p[ev_ok]
    y = y_word[words]
    if np.any(y < 0):
        i = int(words[np.flatnonzero(y < 0)[0]])
        raise EigsError(path, f"event at byte {base + 2 * i} comes before any EVT_ADDR_Y: corrupted or cut file")
    if np.any(x < 0):
        i = int(words[np.flatnonzero(x < 0)[0]])
        raise EigsError(path, f"vector event at byte {base + 2 * i} comes before any VECT_BASE_X: corrupted file")
    return x, y, t_word[words], p


def _decode_evt2x(path: Path, w: np.ndarray, base: int, st: _State, wide: bool) -> EventChunkRaw:
    """EVT 2.0 (``wide`` False, uint32 words) or EVT 2.1 (uint64 words) → raw events (x, y, t, p)."""
    shift = 60 if wide else 28
    nb = 8 if wide else 4
    name = "EVT 2.1" if wide else "EVT 2.0"
    typ = (w >> shift).astype(np.uint8)
    bad = ~np.isin(typ, (0x0, 0x1, 0x8, 0xA, 0xE, 0xF))
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise EigsError(path, f"undefined {name} word type 0x{typ[i]:x} at byte {base + nb * i}: corrupted file")
    st.triggers += int(np.count_nonzero(typ == 0xA))
    st.others += int(np.count_nonzero(typ >= 0xE))
    is_th = typ == 0x8
    th_pos = np.flatnonzero(is_th)
    th_raw = ((w[th_pos] >> 32) if wide else w[th_pos]) & 0x0FFFFFFF
    carried_high = None if st.time_high is None else (st.time_high + (st.loops << 28))
    th = _time_high(path, th_raw, base + nb * th_pos, st, 28, 64)
    k = np.cumsum(is_th) - 1  # index into th of the TIME_HIGH in force, −1 before this chunk's first
    cd = np.flatnonzero(typ <= 1)
    kc = k[cd]
    have = (kc >= 0) | (carried_high is not None)
    if not np.all(have):
        lost = w[cd[~have]]
        st.dropped += (
            int(np.unpackbits((lost & 0xFFFFFFFF).astype("<u4").view(np.uint8)).sum()) if wide else int(lost.size)
        )
        cd, kc = cd[have], kc[have]
    high = th[np.maximum(kc, 0)] if th.size else np.zeros(kc.size, np.int64)
    if carried_high is not None:
        high = np.where(kc >= 0, high, carried_high)
    wc = w[cd]
    lsb_shift = 54 if wide else 22
    t = (high << 6) | ((wc >> lsb_shift) & 0x3F).astype(np.int64)
    pol = (typ[cd] & 1).astype(np.int64)
    if not wide:
        return ((wc >> 11) & 0x7FF).astype(np.int64), (wc & 0x7FF).astype(np.int64), t, pol
    # EVT 2.1: expand the 32-bit validity masks, events in word order then ascending x
    mask = (wc & 0xFFFFFFFF).astype("<u4")
    bits = np.unpackbits(mask.view(np.uint8).reshape(-1, 4), axis=1, bitorder="little").astype(bool)
    row, col = np.nonzero(bits)
    x = ((wc >> 43) & 0x7FF).astype(np.int64)[row] + col
    y = ((wc >> 32) & 0x7FF).astype(np.int64)[row]
    return x, y, t[row], pol[row]


def _decode_dat(path: Path, w: np.ndarray, base: int, st: _State) -> EventChunkRaw:
    """DAT records (n,) uint64 (little-endian: low half = timestamp, high half = address) → raw events."""
    t = (w & 0xFFFFFFFF).astype(np.int64)
    a = w >> 32
    p = ((a >> 28) & 0xF).astype(np.int64)
    bad = p > 1
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise EigsError(path, f"polarity {int(p[i])} of the event at byte {base + 8 * i}; DAT CD events have 0 or 1")
    return (a & 0x3FFF).astype(np.int64), ((a >> 14) & 0x3FFF).astype(np.int64), t, p


def decode(
    path: Path, header: Header, chunk_bytes: int | None = None, state: _State | None = None
) -> Iterator[EventChunkRaw]:
    """Decode the events of a Prophesee file in chunks → raw (x, y, t µs, p {0, 1}) int64 arrays per chunk.

    ``chunk_bytes``: encoded bytes per step (default :data:`CHUNK_WORDS` words: bounded memory even for EVT 3.0
    vectors and EVT 2.1 masks, which expand to up to 12 / 32 events per word). ``state`` (optional) is updated as
    decoding goes (counts of dropped events, triggers, other words).
    """
    st = state if state is not None else _State()
    nb = WORD_BYTES[header.encoding]
    if chunk_bytes is None:
        chunk_bytes = CHUNK_WORDS[header.encoding] * nb
    dtype = {2: "<u2", 4: "<u4", 8: "<u8"}[nb]
    step = max(nb, chunk_bytes - chunk_bytes % nb)
    with open(path, "rb") as fh:
        fh.seek(header.data_start)
        pos = header.data_start
        while True:
            buf = fh.read(step)
            if not buf:
                return
            whole = len(buf) - len(buf) % nb
            if whole != len(buf):
                raise EigsError(
                    path, f"truncated: the file ends inside a {nb}-byte word at byte {pos + whole} (cut file)"
                )
            w = np.frombuffer(buf, dtype=dtype)
            if header.encoding == "evt3":
                out = _decode_evt3(path, w, pos, st)
            elif header.encoding == "dat":
                out = _decode_dat(path, w, pos, st)
            else:
                out = _decode_evt2x(path, w, pos, st, wide=header.encoding == "evt21")
            yield out
            pos += len(buf)


def read_prophesee_events(
    path: Path, header: Header, width: int, height: int, chunk_bytes: int | None = None, state: _State | None = None
) -> Iterator[EventChunk]:
    """Stream the CD events as converted chunks (x, y uint16; t int64 µs; p int8 ±1), checked for time order and
    the sensor size."""
    where = str(path)
    order = TimeOrder(path, "corrupted file")
    offset = 0
    for x, y, t, p in decode(path, header, chunk_bytes, state):
        t = t + header.t0_us if header.t0_us else t
        order(t, offset)
        xs = to_pixel(x, width, "x", where, offset)
        ys = to_pixel(y, height, "y", where, offset)
        yield xs, ys, t, (p.astype(np.int8) << 1) - np.int8(1)
        offset += t.size


def open_prophesee_source(source: str, opts: IngestOptions) -> RawSource:
    """Open a Prophesee RAW (EVT 2.0 / 2.1 / 3.0) or DAT file as a :class:`RawSource` (events only)."""
    from eigs.ingest.poses import read_groundtruth

    opts.refuse("prophesee", "time_unit", "frames", "exposure_us")
    path = Path(source)
    if not path.is_file():
        raise EigsError(path, "no such file")
    if path.suffix.lower() not in (".raw", ".dat"):
        raise EigsError(path, f"unknown extension {path.suffix!r}; Prophesee files end in .raw or .dat")
    header = read_header(path)
    nb = WORD_BYTES[header.encoding]
    size = path.stat().st_size - header.data_start
    src = RawSource(path=path, fmt="prophesee", name=path.stem, width=header.width, height=header.height)
    src.n_events = size // nb if header.encoding in ("evt2", "dat") else None
    state = _State()
    src.notes.append(f"{ENCODINGS[header.encoding]}, {size:,} bytes of events")
    if header.t0_us:
        src.notes.append(f"header t0 {header.t0_us} µs: the time origin it declares, added to every timestamp")
    if opts.groundtruth is not None:
        src.trajectory = read_groundtruth(Path(opts.groundtruth))

    def events(w: int, h: int) -> Iterator[EventChunk]:
        yield from read_prophesee_events(path, header, w, h, state=state)
        if state.dropped:
            src.notes.append(f"{state.dropped} CD events before the first EVT_TIME_HIGH dropped (no time)")
        if state.triggers or state.others:
            src.notes.append(f"{state.triggers} trigger and {state.others} other words not stored")

    src.events = events
    return src
