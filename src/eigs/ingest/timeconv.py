"""Exact unit conversions: timestamps → int64 µs, polarity → int8 ±1, coordinates → uint16.

Rules (``docs/ingestion.md``): integer timestamps are scaled exactly (ns → µs rounds half up); float timestamps
are first rounded to integer nanoseconds when float64 can hold them, then to µs (half up); beyond that range
they must lie within 0.25 µs of an integer µs, else the conversion cannot be proven and is refused.
"""

from __future__ import annotations

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import TIME_UNITS

_NS_EXACT = float(2**53)  # float64 holds every integer below this


def to_us(t: np.ndarray, unit: str, where: str, offset: int = 0) -> np.ndarray:
    """(N,) timestamps in ``unit`` (s, ms, us, ns) → (N,) int64 µs. EigsError (naming ``where``) for NaN/Inf,
    overflow, or float values that cannot be converted exactly. ``offset``: index of t[0] in the file (messages)."""
    ns_per = TIME_UNITS[unit]
    if t.size == 0:
        return np.zeros(0, np.int64)
    if t.dtype.kind in "iu":
        if t.dtype.kind == "u" and t.dtype.itemsize == 8 and int(t.max()) >= 2**63:
            raise EigsError(where, f"timestamp {int(t.max())} does not fit int64")
        ti = t.astype(np.int64, copy=False)
        if ns_per >= 1000:
            factor = ns_per // 1000
            if factor > 1:
                lim = np.iinfo(np.int64).max // factor
                if int(ti.max()) > lim or int(ti.min()) < -lim:
                    raise EigsError(where, f"timestamps in {unit} overflow int64 µs")
                return ti * factor
            return ti.copy() if ti is t else ti
        return (ti + 500) // 1000  # ns → µs, half up
    if t.dtype.kind == "b" or t.dtype.kind not in "f":
        raise EigsError(where, f"timestamps have dtype {t.dtype}, expected integers or floats")
    tf = t.astype(np.float64, copy=False)
    if not np.all(np.isfinite(tf)):
        i = int(np.flatnonzero(~np.isfinite(tf))[0])
        raise EigsError(where, f"timestamp of event {offset + i} is {tf[i]} (NaN/Inf)")
    ns = tf * ns_per
    if float(np.abs(ns).max()) < _NS_EXACT:
        nsi = np.rint(ns).astype(np.int64)
        return (nsi + 500) // 1000
    us = tf * (ns_per / 1000)
    ri = np.rint(us)
    off = np.abs(us - ri)
    if float(off.max()) > 0.25:
        i = int(np.argmax(off))
        raise EigsError(
            where,
            f"float timestamp {float(tf[i])!r} {unit} (event {offset + i}) is too large to convert to µs exactly "
            "(float64 resolution); store integer timestamps",
        )
    return ri.astype(np.int64)


class PolarityMapper:
    """Maps polarity chunks to int8 ±1, accepting {0, 1}, {−1, 1} or bool, and refusing a file that mixes 0 and −1
    or holds anything else. Stateful across the chunks of one file."""

    def __init__(self, where: str):
        self.where = where
        self.seen_zero = False
        self.seen_minus = False

    def __call__(self, p: np.ndarray, offset: int = 0) -> np.ndarray:
        """(N,) polarity → (N,) int8 ±1; ``offset``: index of p[0] in the file (messages)."""
        if p.dtype.kind == "b":
            self.seen_zero = self.seen_zero or bool(np.any(~p))
            self._check()
            return np.where(p, np.int8(1), np.int8(-1))
        if p.dtype.kind not in "iuf":
            raise EigsError(self.where, f"polarity has dtype {p.dtype}, expected integers or bool")
        if p.size == 0:
            return np.zeros(0, np.int8)
        if p.dtype.kind == "f" and not np.all(np.isfinite(p)):
            i = int(np.flatnonzero(~np.isfinite(p))[0])
            raise EigsError(self.where, f"polarity of event {offset + i} is {p[i]} (NaN/Inf)")
        lo, hi = p.min(), p.max()
        if lo >= 0 and hi <= 1 and p.dtype.kind in "iu":
            self.seen_zero = self.seen_zero or bool(lo == 0)
            self._check()
            return (p.astype(np.int8) << 1) - np.int8(1)
        zero, one, minus = p == 0, p == 1, p == -1
        bad = ~(zero | one | minus)
        if np.any(bad):
            i = int(np.flatnonzero(bad)[0])
            raise EigsError(self.where, f"polarity of event {offset + i} is {p[i]}; expected 0/1 or −1/+1")
        self.seen_zero = self.seen_zero or bool(np.any(zero))
        self.seen_minus = self.seen_minus or bool(np.any(minus))
        self._check()
        return np.where(one, np.int8(1), np.int8(-1))

    def _check(self) -> None:
        if self.seen_zero and self.seen_minus:
            raise EigsError(self.where, "polarity mixes 0 and −1 values; cannot tell which encoding the file uses")


def to_pixel(a: np.ndarray, size: int, axis: str, where: str, offset: int = 0) -> np.ndarray:
    """(N,) pixel coordinates (integer, or integral floats) → (N,) uint16; EigsError when outside [0, size)."""
    if a.size == 0:
        return np.zeros(0, np.uint16)
    if a.dtype.kind == "f":
        if not np.all(np.isfinite(a)) or np.any(a != np.floor(a)):
            i = int(np.flatnonzero(~np.isfinite(a) | (a != np.floor(a)))[0])
            raise EigsError(where, f"{axis} of event {offset + i} is {a[i]}, not an integer pixel")
    elif a.dtype.kind not in "iu":
        raise EigsError(where, f"{axis} coordinates have dtype {a.dtype}, expected integers")
    lo, hi = a.min(), a.max()
    if lo < 0 or hi >= size:
        bad = int(np.flatnonzero((a < 0) | (a >= size))[0])
        raise EigsError(
            where,
            f"{axis} of event {offset + bad} is {a[bad]}, outside the sensor (0 ≤ {axis} < {size})",
        )
    return a.astype(np.uint16, copy=False)
