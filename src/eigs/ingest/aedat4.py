"""DAVIS AEDAT 4 recordings (``--format aedat4``) through the ``aedat`` decoder (PyPI, Rust).

One ``events`` stream (t int64 absolute Unix µs, x column, y row, polarity bool: True = ON → +1) and at most one
``frame`` stream (8-bit gray ``L``, ``RGB`` or ``RGBA`` composited on black) whose exposure is
[exposure_begin_t, exposure_end_t) µs on the same clock. IMU and trigger streams are counted, not stored.
Timestamps are kept absolute. AEDAT 4 carries no calibration: give ``--intrinsics``.

The file is decoded three times (frame metadata and counts; pixels of the kept frames; events), so memory stays
at one chunk of events plus the kept frames.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import IngestOptions
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import to_pixel, to_us

log = logging.getLogger(__name__)

CHUNK_EVENTS = 1 << 22
FRAME_CHANNELS = {"L": 1, "RGB": 3, "RGBA": 3}


def _decoder(path: Path):
    import aedat

    try:
        return aedat.Decoder(str(path))
    except Exception as err:  # the Rust decoder raises its own exception types
        raise EigsError(path, f"not a readable AEDAT 4 file ({err})") from None


def _packets(path: Path) -> Iterator[dict]:
    """All packets; a decoding error (truncated or corrupted file) becomes an EigsError."""
    dec = _decoder(path)
    it = iter(dec)
    while True:
        try:
            pk = next(it)
        except StopIteration:
            return
        except Exception as err:
            raise EigsError(path, f"truncated or corrupted AEDAT 4 file ({err})") from None
        yield pk


def _frame_pixels(path: Path, fr: dict, k: int) -> np.ndarray:
    a = np.asarray(fr["pixels"], dtype=np.uint8)
    fmt = fr["format"]
    if fmt == "L":
        a = a.reshape(fr["height"], fr["width"], 1)
    elif fmt == "RGBA":
        from eigs.ingest.images import composite_on_black

        a = composite_on_black(a.reshape(fr["height"], fr["width"], 4))
    else:
        a = a.reshape(fr["height"], fr["width"], 3)
    return a


def open_aedat4_source(source: str, opts: IngestOptions) -> RawSource:
    """Open an AEDAT 4 file as a :class:`RawSource` (first pass: streams, frame metadata, event count)."""
    from eigs.util.progress import progress

    opts.refuse("aedat4", "time_unit", "frames")
    path = Path(source)
    if not path.is_file():
        raise EigsError(path, "no such file")
    with open(path, "rb") as fh:
        magic = fh.read(12)
    if not magic.startswith(b"#!AER-DAT4"):
        raise EigsError(path, f"not an AEDAT 4 file (starts with {magic[:12]!r}, expected '#!AER-DAT4.0')")
    streams = _decoder(path).id_to_stream()
    ev_ids = [i for i, s in streams.items() if s.get("type") == "events"]
    fr_ids = [i for i, s in streams.items() if s.get("type") == "frame"]
    if len(ev_ids) > 1 or len(fr_ids) > 1:
        raise EigsError(
            path, f"holds {len(ev_ids)} event and {len(fr_ids)} frame streams; eigs reads at most one of each"
        )
    if not ev_ids and not fr_ids:
        raise EigsError(path, "holds neither an event nor a frame stream")
    sizes = {(streams[i]["width"], streams[i]["height"]) for i in ev_ids + fr_ids}
    if len(sizes) != 1:
        raise EigsError(path, f"streams differ in size: {sorted(sizes)}")
    width, height = sizes.pop()
    ev_id = ev_ids[0] if ev_ids else None
    fr_id = fr_ids[0] if fr_ids else None

    meta: list[tuple[int, int, int]] = []
    fmts: set[str] = set()
    n_events = 0
    last_t: int | None = None
    other = 0
    for pk in progress(_packets(path), desc=f"scan {path.name}", unit="packet"):
        sid = pk["stream_id"]
        if sid == ev_id and "events" in pk:
            t = pk["events"]["t"]
            if t.size:
                if last_t is not None and int(t[0]) < last_t or np.any(t[1:] < t[:-1]):
                    raise EigsError(path, f"event timestamps go backwards near event {n_events}")
                last_t = int(t[-1])
            n_events += int(t.size)
        elif sid == fr_id and "frame" in pk:
            fr = pk["frame"]
            if fr["format"] not in FRAME_CHANNELS:
                raise EigsError(path, f"frame {len(meta)} has format {fr['format']!r}; eigs reads L, RGB, RGBA")
            if (fr["width"], fr["height"]) != (width, height) or fr["offset_x"] or fr["offset_y"]:
                raise EigsError(
                    path, f"frame {len(meta)} is a region of interest, not the full {width}×{height} sensor"
                )
            if fr["exposure_end_t"] < fr["exposure_begin_t"]:
                raise EigsError(path, f"frame {len(meta)} exposure ends before it starts")
            fmts.add(fr["format"])
            meta.append((fr["t"], fr["exposure_begin_t"], fr["exposure_end_t"]))
        else:
            other += 1
    if len({FRAME_CHANNELS[f] for f in fmts}) > 1:
        raise EigsError(path, f"frames mix formats {sorted(fmts)}")

    src = RawSource(path=path, fmt="aedat4", name=path.stem, width=int(width), height=int(height))
    kinds = ", ".join(f"{i}:{s.get('type')}" for i, s in sorted(streams.items()))
    src.notes.append(f"streams {kinds}; {other} other packets (IMU, triggers) not stored")
    if meta:
        m = np.asarray(meta, dtype=np.uint64)
        if int(m.max()) >= 2**63:
            raise EigsError(path, "frame timestamps do not fit int64")
        m = m.astype(np.int64)
        back = np.flatnonzero(np.diff(m[:, 1]) < 0)
        if back.size:
            raise EigsError(path, f"frame exposures go backwards at frame {int(back[0]) + 1}")
        src.n_frames = m.shape[0]
        src.frame_t_us = m[:, 0]
        src.exposure_us = np.ascontiguousarray(m[:, 1:3])

        def load(idx: np.ndarray) -> np.ndarray:
            want = {int(i): j for j, i in enumerate(idx)}
            out: list[np.ndarray | None] = [None] * len(idx)
            k = 0
            for pk in _packets(path):
                if pk["stream_id"] == fr_id and "frame" in pk:
                    if k in want:
                        out[want[k]] = _frame_pixels(path, pk["frame"], k)
                    k += 1
            if any(a is None for a in out):
                raise EigsError(path, "the file changed while reading (frame count differs between passes)")
            return np.stack(out)  # type: ignore[arg-type]

        src.load_frames = load
    if ev_id is not None:
        src.n_events = n_events
        src.events = lambda w, h: _read_events(path, ev_id, w, h)
    return src


def _read_events(path: Path, ev_id: int, width: int, height: int, chunk: int = CHUNK_EVENTS) -> Iterator[EventChunk]:
    """Events of stream ``ev_id`` re-batched into chunks of about ``chunk`` events (converted units)."""
    where = str(path)
    buf: list[np.ndarray] = []
    nbuf = 0
    offset = 0

    def flush() -> EventChunk:
        ev = np.concatenate(buf) if len(buf) > 1 else buf[0]
        t = to_us(ev["t"], "us", where, offset)
        x = to_pixel(ev["x"], width, "x", where, offset)
        y = to_pixel(ev["y"], height, "y", where, offset)
        p = np.where(ev["on"], np.int8(1), np.int8(-1))
        return x, y, t, p

    for pk in _packets(path):
        if pk["stream_id"] == ev_id and "events" in pk:
            ev = pk["events"]
            buf.append(ev)
            nbuf += ev.shape[0]
            if nbuf >= chunk:
                out = flush()
                yield out
                offset += nbuf
                buf, nbuf = [], 0
    if nbuf:
        yield flush()
