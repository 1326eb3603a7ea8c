"""Spec-following encoders of Prophesee RAW (EVT 2.0, 2.1, 3.0) and DAT files, for the tests.

Written from Prophesee's format pages (docs.prophesee.ai: "EVT 2.0 Format", "EVT 2.1 Format", "EVT 3.0 Format",
"DAT File Format"), independently of :mod:`eigs.ingest.prophesee`: a plain loop over events that emits words the way
a sensor would (a TIME_HIGH word whenever the high part changes — EVT 3.0: every 4096 µs step in between —,
EVT 3.0 rows and vectors for runs of neighbouring pixels), plus trigger and OTHERS words the decoder must skip.

Events: (x, y, t µs, p {0, 1}) integer arrays, t non-decreasing. The decoder must return exactly these.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np


def _runs(x, y, t, p, max_span: int):
    """Consecutive events with equal (t, y, p) and strictly increasing x within ``max_span`` of the first."""
    i, n = 0, len(t)
    while i < n:
        j = i + 1
        while j < n and t[j] == t[i] and y[j] == y[i] and p[j] == p[i] and x[j] > x[j - 1] and x[j] - x[i] < max_span:
            j += 1
        yield i, j
        i = j


def encode_evt2(x, y, t, p, trigger_every: int = 97) -> bytes:
    words: list[int] = []
    th = None
    for k in range(len(t)):
        hi = (int(t[k]) >> 6) & 0x0FFFFFFF
        if hi != th:
            words.append((0x8 << 28) | hi)
            th = hi
        words.append((int(p[k]) << 28) | ((int(t[k]) & 0x3F) << 22) | (int(x[k]) << 11) | int(y[k]))
        if k % trigger_every == 5:
            words.append((0xA << 28) | ((int(t[k]) & 0x3F) << 22) | (1 << 8) | 1)  # EXT_TRIGGER id 1, rising
            words.append((0xE << 28) | 0x123)  # OTHERS
            words.append((0xF << 28) | 0x456)  # CONTINUED
    return struct.pack(f"<{len(words)}I", *words)


def encode_evt21(x, y, t, p) -> bytes:
    """One 64-bit word per run of events with equal (t, y, p) inside one 32-aligned block of x."""
    words: list[int] = []
    th = None
    i, n = 0, len(t)
    while i < n:
        hi = (int(t[i]) >> 6) & 0x0FFFFFFF
        if hi != th:
            words.append((0x8 << 60) | (hi << 32))
            th = hi
        base = int(x[i]) & ~31
        mask = 1 << (int(x[i]) - base)
        j = i + 1
        while j < n and t[j] == t[i] and y[j] == y[i] and p[j] == p[i] and x[j] > x[j - 1] and int(x[j]) - base < 32:
            mask |= 1 << (int(x[j]) - base)
            j += 1
        words.append((int(p[i]) << 60) | ((int(t[i]) & 0x3F) << 54) | (base << 43) | (int(y[i]) << 32) | mask)
        i = j
    words.insert(len(words) // 2, (0xA << 60) | 1)  # a trigger in the middle
    return struct.pack(f"<{len(words)}Q", *words)


def encode_evt3(x, y, t, p, first_high: bool = True) -> bytes:
    words: list[int] = []
    th = None  # absolute t >> 12 last emitted
    tl = None
    cur_y = None
    use12 = True
    for i, j in _runs(x, y, t, p, 20):
        ti = int(t[i])
        hi = ti >> 12
        if th is None:
            if first_high:
                words.append((0x8 << 12) | (hi & 0xFFF))
            th, tl = hi, None
        while th < hi:  # the sensor emits every TIME_HIGH step
            th += 1
            words.append((0x8 << 12) | (th & 0xFFF))
            tl = None
        if tl != (ti & 0xFFF):
            tl = ti & 0xFFF
            words.append((0x6 << 12) | tl)
        if cur_y != int(y[i]):
            cur_y = int(y[i])
            words.append((0x0 << 12) | cur_y)
        if j - i == 1:
            words.append((0x2 << 12) | (int(p[i]) << 11) | int(x[i]))
            continue
        bx = int(x[i])
        words.append((0x3 << 12) | (int(p[i]) << 11) | bx)
        xs = [int(v) for v in x[i:j]]
        while xs:
            width = 12 if use12 else 8
            use12 = not use12
            mask = 0
            for v in [v for v in xs if v < bx + width]:
                mask |= 1 << (v - bx)
            xs = [v for v in xs if v >= bx + width]
            words.append(((0x4 if width == 12 else 0x5) << 12) | mask)
            bx += width
        if i % 7 == 0:
            words.append((0xE << 12) | 0x001)  # OTHERS + CONTINUED_12 + CONTINUED_4 payloads
            words.append((0xF << 12) | 0xABC)
            words.append((0x7 << 12) | 0x5)
            words.append((0xA << 12) | 0x101)  # EXT_TRIGGER
    return struct.pack(f"<{len(words)}H", *words)


def write_raw(
    path: Path, encoding: str, x, y, t, p, width: int, height: int, old_header: bool = False, t0=None, **kw
) -> None:
    """A RAW file: the ``%`` header then the encoded words. ``encoding``: evt2, evt21 or evt3. ``t0``: a ``% t0``
    header line with that value (as faery writes it) and the times stored relative to it."""
    if t0 is not None:
        t = np.asarray(t) - int(t0)
    body = {"evt2": encode_evt2, "evt21": encode_evt21, "evt3": encode_evt3}[encoding](x, y, t, p, **kw)
    if old_header:
        ver = {"evt2": "2.0", "evt21": "2.1", "evt3": "3.0"}[encoding]
        head = f"% Date 2026-11-27 10:00:00\n% evt {ver}\n% geometry {width}x{height}\n"
    else:
        name = {"evt2": "EVT2", "evt21": "EVT21", "evt3": "EVT3"}[encoding]
        head = (
            "% camera_integrator_name Prophesee\n% date 2026-11-27 10:00:00\n"
            f"% format {name};height={height};width={width}\n% generation 4.2\n% end\n"
        )
    if t0 is not None:
        head = head.replace("% end\n", "") + f"% t0 {t0}\n" + ("" if old_header else "% end\n")
    path.write_bytes(head.encode("ascii") + body)


def write_dat(path: Path, x, y, t, p, width: int, height: int) -> None:
    head = (
        "% Data file containing CD events.\n% Version 2\n% Date 2026-11-27 10:00:00\n"
        f"% Height {height}\n% Width {width}\n"
    )
    rec = np.zeros(len(t), dtype=[("t", "<u4"), ("a", "<u4")])
    rec["t"] = t
    rec["a"] = (np.asarray(p, np.uint32) << 28) | (np.asarray(y, np.uint32) << 14) | np.asarray(x, np.uint32)
    path.write_bytes(head.encode("ascii") + bytes([0x0C, 8]) + rec.tobytes())


def known_events(n: int, width: int, height: int, t0: int = 0, seed: int = 0, gap_us: int = 40):
    """Events in bursts: runs of neighbouring pixels in one row at one time (vectors), and single events.

    Returns (x, y, t, p) int64 arrays, t non-decreasing."""
    rng = np.random.default_rng(seed)
    xs, ys, ts, ps = [], [], [], []
    t = t0
    while len(ts) < n:
        t += int(rng.integers(0, gap_us))
        y, pol = int(rng.integers(0, height)), int(rng.integers(0, 2))
        if rng.random() < 0.5:  # a run of neighbours (some gaps) in one row
            start = int(rng.integers(0, width - 1))
            cand = np.arange(start, min(width, start + int(rng.integers(2, 40))))
            keep = cand[rng.random(cand.size) < 0.7]
            if keep.size == 0:
                keep = cand[:1]
        else:
            keep = np.array([int(rng.integers(0, width))])
        for xv in keep:
            xs.append(int(xv))
            ys.append(y)
            ts.append(t)
            ps.append(pol)
    return tuple(np.asarray(a[:n], np.int64) for a in (xs, ys, ts, ps))
