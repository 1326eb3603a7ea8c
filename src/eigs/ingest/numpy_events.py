"""NumPy event arrays (``--format numpy``): ``.npy`` / ``.npz`` files, streamed in chunks.

Layouts (``.npz``: first match wins):

- four 1-D members named ``t, x, y, p`` (aliases ``ts``/``timestamp(s)``/``time``, ``xs``, ``ys``,
  ``ps``/``pol``/``polarity``) — EventNeRF's npz;
- one array (the ``.npy`` itself, or an ``.npz`` member named ``events``, or its only array) that is either
  **structured** with those field names, or **2-D numeric** (N, K) whose columns ``--columns`` names in order
  (``t,x,y,p``, ``x,y,t,p``, …; ``-`` skips a column) — e.g. BeNeRF's ``events.npy``. A column order is never
  guessed. (K, N) arrays (one row per field) are read the same way when ``--columns`` has K entries and N ≠ K.

Units are never guessed: ``--time-unit s|ms|us|ns`` is required (npy files carry no units). Polarity: {0, 1},
{−1, +1} or bool (:class:`~eigs.ingest.timeconv.PolarityMapper`). Sensor size: ``--sensor-size``, the ``.npz``
scalar members ``width``/``height``, or the frames. Frames and exposures come from the same sidecar as for
``h5`` (``--frames FILE``, default ``<file stem>.frames.txt`` beside the file).

Memory: the arrays are never loaded whole. Each is read through its ``.npy`` header and then in chunks of
:data:`CHUNK_EVENTS` rows from the file (``.npy``) or the zip member's stream (``.npz``, stored or deflated), so
a compressed ``.npz`` larger than memory converts too. A short read (truncated file) or a zip CRC error is an
error naming the file and the event.
"""

from __future__ import annotations

import io
import logging
import zipfile
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.chunks import TimeOrder
from eigs.ingest.options import TIME_UNITS, IngestOptions
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import PolarityMapper, to_pixel, to_us

log = logging.getLogger(__name__)

CHUNK_EVENTS = 1 << 22
ALIASES = {
    "t": ("t", "ts", "timestamp", "timestamps", "time"),
    "x": ("x", "xs"),
    "y": ("y", "ys"),
    "p": ("p", "ps", "pol", "polarity", "polarities"),
}
FIELDS = ("t", "x", "y", "p")


@dataclass
class _Header:
    """What a ``.npy`` header says: shape, Fortran order, dtype, and the byte offset of the data."""

    shape: tuple[int, ...]
    fortran: bool
    dtype: np.dtype
    data_start: int


def _read_header(fh: BinaryIO, path: Path, what: str) -> _Header:
    fmt = np.lib.format
    try:
        version = fmt.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = fmt.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = fmt.read_array_header_2_0(fh)
        else:
            raise EigsError(path, f"{what}: npy format version {version} is not supported (1.0 and 2.0 are)")
    except EigsError:
        raise
    except Exception as err:  # numpy's header parser raises ValueError, SyntaxError, TokenError, ... on damage
        raise EigsError(path, f"{what}: not a readable .npy array ({str(err).splitlines()[0][:120]})") from None
    if dtype.hasobject:
        raise EigsError(path, f"{what} holds Python objects (pickled); eigs reads numeric arrays only")
    return _Header(tuple(int(s) for s in shape), bool(fortran), dtype, fh.tell())


class _Member(io.RawIOBase):
    """A readable, forward-seekable stream of one zip member that closes its archive with it."""

    def __init__(self, zf: zipfile.ZipFile, member: str):
        super().__init__()
        self.zf = zf
        try:
            self.fh = zf.open(member)
        except BaseException:
            zf.close()
            raise

    def readable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        return self.fh.read(n)

    def readinto(self, b) -> int:  # type: ignore[override]
        data = self.fh.read(len(b))
        b[: len(data)] = data
        return len(data)

    def seek(self, pos: int, whence: int = 0) -> int:
        return self.fh.seek(pos, whence)

    def tell(self) -> int:
        return self.fh.tell()

    def close(self) -> None:
        if not self.closed:
            self.fh.close()
            self.zf.close()
        super().close()


class _Array:
    """One ``.npy`` array in a file or an ``.npz`` member, opened as many times as needed (one handle per
    column block) and read forward in chunks."""

    def __init__(self, path: Path, member: str | None):
        self.path = path
        self.member = member
        self.where = "the array" if member is None else f"member {member}"
        with self.open() as fh:
            self.header = _read_header(fh, path, self.where)

    def open(self) -> BinaryIO:
        try:
            if self.member is None:
                return open(self.path, "rb")
            return _Member(zipfile.ZipFile(self.path), self.member)
        except (OSError, zipfile.BadZipFile, KeyError, zlib.error) as err:
            raise EigsError(self.path, f"cannot open ({str(err).splitlines()[0][:120]})") from None

    def blocks(self, start_byte: int, itemsize: int, n: int, chunk: int) -> Iterator[bytes]:
        """Raw bytes of ``n`` items of ``itemsize`` bytes from data byte ``start_byte``, ``chunk`` items at a time."""
        fh = self.open()
        try:
            fh.seek(self.header.data_start + start_byte)
            done = 0
            while done < n:
                k = min(chunk, n - done)
                buf = fh.read(k * itemsize)
                if len(buf) != k * itemsize:
                    raise EigsError(
                        self.path,
                        f"truncated: {self.where} ends at event {done + len(buf) // itemsize} of {n}",
                    )
                yield buf
                done += k
        except (OSError, zlib.error, zipfile.BadZipFile, EOFError) as err:
            raise EigsError(self.path, f"corrupted data in {self.where} ({str(err).splitlines()[0][:120]})") from None
        finally:
            fh.close()


def _field_names(names: tuple[str, ...] | list[str]) -> dict[str, str]:
    """Map t/x/y/p → the name used in a structured dtype or an npz (aliases, case-insensitive)."""
    low = {n.lower(): n for n in names}
    found = {}
    for f, aliases in ALIASES.items():
        hits = [low[a] for a in aliases if a in low]
        if len(hits) > 1:
            raise ValueError(f"both {hits[0]!r} and {hits[1]!r} could be {f}")
        if hits:
            found[f] = hits[0]
    return found


def parse_columns(spec: str) -> list[str]:
    """``--columns``: comma-separated t, x, y, p (each once) and ``-`` for columns to skip → list of names."""
    cols = [c.strip().lower() for c in spec.split(",")]
    if any(c not in (*FIELDS, "-") for c in cols) or sorted(c for c in cols if c != "-") != sorted(FIELDS):
        raise EigsError("--columns", f"expected t, x, y, p each once (and - for skipped columns), got {spec!r}")
    return cols


@dataclass
class _Plan:
    """How to read the four fields: per field, (array, byte offset of its first value, byte stride is implicit)."""

    n: int
    layout: str
    read: Callable[[int], Iterator[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]]


def _plan_records(arr: _Array, cols: list[str] | None) -> _Plan:
    """A single array: structured (N,), numeric (N, K) C order, or numeric (N, K) Fortran / (K, N) C order."""
    h = arr.header
    if h.dtype.names is not None:
        if cols is not None:
            raise EigsError(
                "--columns", f"{arr.path} ({arr.where}) is a structured array whose fields have names; omit --columns"
            )
        if len(h.shape) != 1:
            raise EigsError(arr.path, f"{arr.where}: structured array of shape {h.shape}, expected one dimension")
        try:
            names = _field_names(list(h.dtype.names))
        except ValueError as err:
            raise EigsError(arr.path, f"{arr.where}: ambiguous fields: {err}") from None
        missing = [f for f in FIELDS if f not in names]
        if missing:
            raise EigsError(
                arr.path, f"{arr.where}: no field for {', '.join(missing)} (fields: {', '.join(h.dtype.names)})"
            )
        n = h.shape[0]
        dt = h.dtype

        def read_struct(chunk: int):
            for buf in arr.blocks(0, dt.itemsize, n, chunk):
                rec = np.frombuffer(buf, dtype=dt)
                yield tuple(rec[names[f]] for f in FIELDS)

        return _Plan(n, f"structured array {arr.where} (fields {', '.join(names[f] for f in FIELDS)})", read_struct)

    if h.dtype.kind not in "iuf" or len(h.shape) != 2:
        raise EigsError(
            arr.path,
            f"{arr.where}: {h.dtype} array of shape {h.shape}; expected a structured array with t, x, y, p fields or "
            "a 2-D numeric (N, K) array with --columns",
        )
    if cols is None:
        raise EigsError(
            "--columns",
            f"{arr.path} ({arr.where}) is a plain {h.shape[0]}×{h.shape[1]} array: say which column is which, "
            "e.g. --columns t,x,y,p",
        )
    k = len(cols)
    rows, ncol = h.shape
    if ncol == k and not (rows == k and h.fortran):
        n, by_row = rows, not h.fortran
    elif rows == k:
        n, by_row = ncol, h.fortran
    else:
        raise EigsError(arr.path, f"{arr.where} has shape {h.shape}; --columns names {k} columns")
    item = h.dtype.itemsize
    if by_row:  # each event's K values are contiguous

        def read_rows(chunk: int):
            for buf in arr.blocks(0, item * k, n, chunk):
                a = np.frombuffer(buf, dtype=h.dtype).reshape(-1, k)
                yield tuple(a[:, cols.index(f)] for f in FIELDS)

        return _Plan(n, f"{h.shape} array {arr.where}, columns {','.join(cols)}", read_rows)

    def read_blocks(chunk: int):  # each field's N values are contiguous: one stream per field
        its = [arr.blocks(cols.index(f) * n * item, item, n, chunk) for f in FIELDS]
        for bufs in zip(*its, strict=True):
            yield tuple(np.frombuffer(b, dtype=h.dtype) for b in bufs)

    return _Plan(n, f"{h.shape} array {arr.where} (one row per field), columns {','.join(cols)}", read_blocks)


def _plan_members(path: Path, members: dict[str, str]) -> _Plan:
    """Four 1-D npz members, one per field."""
    arrs = {f: _Array(path, members[f] + ".npy") for f in FIELDS}
    for a in arrs.values():
        if len(a.header.shape) != 1 or a.header.dtype.names is not None:
            raise EigsError(path, f"{a.where} has shape {a.header.shape}, expected a 1-D array")
    lens = {a.where: a.header.shape[0] for a in arrs.values()}
    if len(set(lens.values())) != 1:
        raise EigsError(path, "event arrays differ in length: " + ", ".join(f"{k} {v}" for k, v in lens.items()))
    n = next(iter(lens.values()))

    def read(chunk: int):
        its = [arrs[f].blocks(0, arrs[f].header.dtype.itemsize, n, chunk) for f in FIELDS]
        for bufs in zip(*its, strict=True):
            yield tuple(np.frombuffer(b, dtype=arrs[f].header.dtype) for f, b in zip(FIELDS, bufs, strict=True))

    return _Plan(n, "npz members " + ", ".join(members[f] for f in FIELDS), read)


def _npz_scalar(path: Path, zf: zipfile.ZipFile, name: str) -> int | None:
    if name + ".npy" not in zf.namelist():
        return None
    try:
        with zf.open(name + ".npy") as fh:
            v = np.lib.format.read_array(fh, allow_pickle=False)
    except (ValueError, OSError, zlib.error, zipfile.BadZipFile, EOFError) as err:
        raise EigsError(path, f"cannot read {name} ({str(err).splitlines()[0][:120]})") from None
    if v.size != 1 or v.dtype.kind not in "iu" or int(v.reshape(())) <= 0:
        raise EigsError(path, f"{name} must be one positive integer, got {v.dtype} {v.shape}")
    return int(v.reshape(()))


def plan_events(path: Path, columns: str | None) -> tuple[_Plan, int | None, int | None]:
    """Decide how to read ``path`` → (plan, width or None, height or None)."""
    cols = parse_columns(columns) if columns is not None else None
    with open(path, "rb") as fh:
        magic = fh.read(6)
    if magic == b"\x93NUMPY":
        return _plan_records(_Array(path, None), cols), None, None
    if not magic.startswith(b"PK"):
        raise EigsError(path, f"neither a .npy array nor an .npz archive (starts with {magic!r})")
    try:
        with zipfile.ZipFile(path) as zf:
            names = [n[:-4] for n in zf.namelist() if n.endswith(".npy")]
            width, height = _npz_scalar(path, zf, "width"), _npz_scalar(path, zf, "height")
    except zipfile.BadZipFile as err:
        raise EigsError(path, f"not a readable .npz archive ({err})") from None
    arrays = [n for n in names if n not in ("width", "height")]
    try:
        members = _field_names(arrays)
    except ValueError as err:
        raise EigsError(path, f"ambiguous members: {err}") from None
    if all(f in members for f in FIELDS):
        if cols is not None:
            raise EigsError("--columns", f"{path} names its arrays ({', '.join(arrays)}); omit --columns")
        return _plan_members(path, members), width, height
    if "events" in arrays:
        one = "events"
    elif len(arrays) == 1:
        one = arrays[0]
    else:
        raise EigsError(
            path,
            f"holds {', '.join(arrays) or 'no arrays'}; expected members t, x, y, p, or one 'events' array",
        )
    return _plan_records(_Array(path, one + ".npy"), cols), width, height


def read_numpy_events(
    path: Path, plan: _Plan, unit: str, width: int, height: int, chunk: int = CHUNK_EVENTS
) -> Iterator[EventChunk]:
    """Stream the events of ``plan`` as converted chunks (x, y uint16; t int64 µs; p int8 ±1)."""
    where = str(path)
    polarity = PolarityMapper(where)
    order = TimeOrder(path)
    offset = 0
    for t_raw, x_raw, y_raw, p_raw in plan.read(chunk):
        t = to_us(np.asarray(t_raw), unit, where, offset)
        order(t, offset)
        x = to_pixel(np.asarray(x_raw), width, "x", where, offset)
        y = to_pixel(np.asarray(y_raw), height, "y", where, offset)
        p = polarity(np.asarray(p_raw), offset)
        yield x, y, t, p
        offset += t.shape[0]


def open_numpy_source(source: str, opts: IngestOptions) -> RawSource:
    """Open a ``.npy`` / ``.npz`` event array (and its optional frames sidecar) as a :class:`RawSource`."""
    from eigs.ingest.h5events import read_sidecar
    from eigs.ingest.images import read_image, read_images
    from eigs.ingest.poses import read_groundtruth

    path = Path(source)
    if not path.is_file():
        raise EigsError(path, "no such file")
    if opts.time_unit is None:
        raise EigsError(
            path, "NumPy arrays carry no time unit; give --time-unit " + "|".join(TIME_UNITS) + " (the unit of t)"
        )
    plan, width, height = plan_events(path, opts.columns)
    src = RawSource(path=path, fmt="numpy", name=path.stem, width=width, height=height, n_events=plan.n)
    src.notes.append(f"layout: {plan.layout}; t in {opts.time_unit} (--time-unit)")

    sidecar = Path(opts.frames) if opts.frames is not None else path.with_name(path.stem + ".frames.txt")
    if opts.frames is not None or sidecar.is_file():
        t, exposure, files = read_sidecar(sidecar)
        first = read_image(files[0])
        fh, fw = first.shape[:2]
        if width is not None and (fw, fh) != (width, height):
            raise EigsError(sidecar, f"frames are {fw}×{fh} but {path.name} says {width}×{height}")
        src.width, src.height = fw, fh
        src.n_frames = len(files)
        src.exposure_us = exposure
        src.frame_t_us = t

        def load(idx: np.ndarray) -> np.ndarray:
            return read_images([files[i] for i in idx], desc="frames")

        src.load_frames = load
        src.notes.append(f"frames from {sidecar}")
    if opts.groundtruth is not None:
        src.trajectory = read_groundtruth(Path(opts.groundtruth))
    unit = opts.time_unit
    src.events = lambda w, h: read_numpy_events(path, plan, unit, w, h)
    return src
