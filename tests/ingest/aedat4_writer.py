"""A minimal AEDAT 4.0 *writer* for test fixtures (uncompressed packets, flatbuffers laid out by hand).

File: ``#!AER-DAT4.0\\r\\n``, u32 length + IOHeader flatbuffer (compression None, XML description of the streams),
then packets ``u32 stream id, u32 length, size-prefixed flatbuffer`` (identifier EVTS or FRME). Schemas (AEDAT 4):
``Event {t: int64, x: int16, y: int16, on: bool}`` (16-byte struct); ``EventPacket {elements: [Event]}``;
``Frame {t, begin_t, end_t, exposure_begin_t, exposure_end_t: int64; format: int8 (0 gray, 16 BGR, 24 BGRA);
width, height, offset_x, offset_y: int16; pixels: [uint8]}``; ``Ioheader {compression: int32, file_data_position:
int64, description: string}``.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def _align(n: int, a: int) -> int:
    return (n + a - 1) // a * a


def flatbuffer(
    ident: bytes | None,
    n_fields: int,
    scalars: dict[int, tuple[str, object]],
    vector: tuple[int, bytes, int, int] | None,
    size_prefixed: bool,
) -> bytes:
    """One root table. ``scalars``: field id → (struct format, value); ``vector``: (field id, element bytes,
    element count, element alignment) — a string is a vector of bytes plus a terminating NUL."""
    base = 4 if size_prefixed else 0
    vt_pos = base + 4 + (4 if ident else 0)
    vt_size = 4 + 2 * n_fields
    table_pos = _align(vt_pos + vt_size, 8)
    offs: dict[int, int] = {}
    cur = 4
    items = sorted(scalars.items(), key=lambda kv: -struct.calcsize(kv[1][0]))
    layout = [(fid, struct.calcsize(fmt)) for fid, (fmt, _) in items]
    if vector is not None:
        layout.insert(sum(1 for _, s in layout if s >= 8), (vector[0], 4))
    for fid, size in layout:
        cur = _align(table_pos + cur, size) - table_pos
        offs[fid] = cur
        cur += size
    table_size = cur
    end = table_pos + table_size
    vec_pos = None
    if vector is not None:
        elem_align = max(vector[3], 4)
        vec_pos = _align(end, 4)
        while (vec_pos + 4) % elem_align:
            vec_pos += 4
        end = vec_pos + 4 + len(vector[1])
    total = _align(end, 8)
    buf = bytearray(total)
    if size_prefixed:
        struct.pack_into("<I", buf, 0, total - 4)
    struct.pack_into("<I", buf, base, table_pos - base)
    if ident:
        buf[base + 4 : base + 8] = ident
    struct.pack_into("<HH", buf, vt_pos, vt_size, table_size)
    for fid, off in offs.items():
        struct.pack_into("<H", buf, vt_pos + 4 + 2 * fid, off)
    struct.pack_into("<i", buf, table_pos, table_pos - vt_pos)
    for fid, (fmt, value) in scalars.items():
        struct.pack_into(fmt, buf, table_pos + offs[fid], value)
    if vector is not None:
        fid, data, count, _ = vector
        struct.pack_into("<I", buf, table_pos + offs[fid], vec_pos - (table_pos + offs[fid]))
        struct.pack_into("<I", buf, vec_pos, count)
        buf[vec_pos + 4 : vec_pos + 4 + len(data)] = data
    return bytes(buf)


def _description(width: int, height: int, with_frames: bool) -> str:
    def stream(i: int, ident: str, name: str) -> str:
        return (
            f'<node name="{i}" path="/mainloop/Recorder/outInfo/{i}/">'
            f'<attr key="compression" type="string">NONE</attr>'
            f'<attr key="originalOutputName" type="string">{name}</attr>'
            f'<attr key="typeIdentifier" type="string">{ident}</attr>'
            f'<node name="info" path="/mainloop/Recorder/outInfo/{i}/info/">'
            f'<attr key="sizeX" type="int">{width}</attr><attr key="sizeY" type="int">{height}</attr>'
            f"</node></node>"
        )

    body = stream(0, "EVTS", "events") + (stream(1, "FRME", "frames") if with_frames else "")
    return f'<dv version="2.0"><node name="outInfo" path="/mainloop/Recorder/outInfo/">{body}</node></dv>'


def event_packet(t: np.ndarray, x: np.ndarray, y: np.ndarray, on: np.ndarray) -> bytes:
    rec = np.zeros(t.shape[0], dtype=[("t", "<i8"), ("x", "<i2"), ("y", "<i2"), ("on", "u1"), ("pad", "V3")])
    rec["t"], rec["x"], rec["y"], rec["on"] = t, x, y, on
    return flatbuffer(b"EVTS", 1, {}, (0, rec.tobytes(), t.shape[0], 8), size_prefixed=True)


def frame_packet(
    t: int, exposure: tuple[int, int], pixels: np.ndarray, fmt: int = 0, offset: tuple[int, int] = (0, 0)
) -> bytes:
    """``pixels``: (H, W) gray, or (H, W, 3) BGR / (H, W, 4) BGRA as AEDAT stores them."""
    h, w = pixels.shape[:2]
    scalars = {
        0: ("<q", t),
        1: ("<q", exposure[0] - 100),
        2: ("<q", exposure[1] + 100),
        3: ("<q", exposure[0]),
        4: ("<q", exposure[1]),
        5: ("<b", fmt),
        6: ("<h", w),
        7: ("<h", h),
        8: ("<h", offset[0]),
        9: ("<h", offset[1]),
    }
    data = np.ascontiguousarray(pixels, dtype=np.uint8).tobytes()
    return flatbuffer(b"FRME", 11, scalars, (10, data, len(data), 1), size_prefixed=True)


def write_aedat4(
    path: Path, width: int, height: int, packets: list[tuple[int, bytes]], with_frames: bool = True
) -> None:
    """``packets``: (stream id 0 = events / 1 = frames, packet bytes) in file order."""
    desc = _description(width, height, with_frames).encode() + b"\0"
    header = flatbuffer(None, 3, {0: ("<i", 0)}, (2, desc, len(desc) - 1, 1), size_prefixed=False)
    with open(path, "wb") as f:
        f.write(b"#!AER-DAT4.0\r\n")
        f.write(struct.pack("<I", len(header)))
        f.write(header)
        for sid, data in packets:
            f.write(struct.pack("<II", sid, len(data)))
            f.write(data)
