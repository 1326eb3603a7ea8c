"""Helpers shared by the streaming event readers of binary formats (Prophesee, AEDAT 2/3.1, NumPy, ROS bags).

- :class:`TimeOrder` refuses timestamps that go backwards across the chunks of one file;
- :class:`Rebatcher` collects small decoded pieces (ROS messages, AEDAT packets) into chunks of about
  ``chunk`` events, so the scene writer sees few large appends and memory stays at one chunk.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.raw import EventChunk


class TimeOrder:
    """Checks that int64 µs timestamps never decrease, chunk after chunk, and names the first offending event."""

    def __init__(self, path: Path | str, hint: str = "unsorted or corrupted file"):
        self.path = path
        self.hint = hint
        self.last: int | None = None

    def __call__(self, t: np.ndarray, offset: int) -> None:
        """``t``: (n,) int64 µs of events [offset, offset + n) of the file."""
        if t.size == 0:
            return
        back = np.flatnonzero(t[1:] < t[:-1])
        if self.last is not None and int(t[0]) < self.last:
            raise EigsError(self.path, f"timestamps go backwards at event {offset} ({self.hint})")
        if back.size:
            raise EigsError(self.path, f"timestamps go backwards at event {offset + int(back[0]) + 1} ({self.hint})")
        self.last = int(t[-1])


class Rebatcher:
    """Accumulates converted event pieces (x, y uint16; t int64 µs; p int8 ±1) into chunks of ≥ ``chunk`` events."""

    def __init__(self, chunk: int):
        self.chunk = chunk
        self.parts: list[EventChunk] = []
        self.n = 0

    def add(self, piece: EventChunk) -> Iterator[EventChunk]:
        """Add a piece; yields a full chunk when enough events are buffered."""
        if piece[2].size:
            self.parts.append(piece)
            self.n += piece[2].size
        if self.n >= self.chunk:
            yield self.flush()

    def flush(self) -> EventChunk:
        """The buffered events as one chunk (empty arrays when nothing is buffered)."""
        if not self.parts:
            e = np.zeros(0, np.int64)
            return e.astype(np.uint16), e.astype(np.uint16), e, e.astype(np.int8)
        out = tuple(np.concatenate([p[k] for p in self.parts]) for k in range(4))
        self.parts, self.n = [], 0
        return out  # type: ignore[return-value]

    def rest(self) -> Iterator[EventChunk]:
        """Yields the last, partial chunk if any events are left."""
        if self.n:
            yield self.flush()
