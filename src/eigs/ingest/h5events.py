"""HDF5 event files (``--format h5``): DSEC and its variants, read in chunks; compressed files via hdf5plugin.

Layouts (first match wins):

- DSEC / TUM-VIE / VECtor: ``events/{x,y,t,p}`` (+ ``t_offset``, ``ms_to_idx``); integer ``t`` is µs by the
  layout's definition, and ``ms_to_idx`` (when present) is checked against it;
- Monash H5Packager: ``events/{xs,ys,ts,ps}``; unit from an attribute or ``--time-unit``;
- flat (Ev-DeblurNeRF): root ``x, y, t, p``; unit from an attribute or ``--time-unit``;
- v2e ``--dvs_h5``: one (N, 4) ``events`` dataset ``[t, x, y, p]``; integer t is µs (v2e's definition).

A unit attribute (``unit``, ``units``, ``time_unit``, ``t_unit`` on the time dataset, its group or the root; values
s, ms, us/µs, ns) overrides the layout default; ``--time-unit`` must agree with it. ``t_offset`` (µs) is added.
Sensor size: attributes ``width``/``height`` (root or ``events``), the frames, or ``--sensor-size``.

Frames and exposures come from a sidecar text file (``--frames FILE``, default ``<file stem>.frames.txt`` beside the
HDF5 file): one frame per line, ``exposure_start_us exposure_end_us image`` or ``t_us image`` (times on the
event clock after ``t_offset``; image paths relative to the sidecar).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import TIME_UNITS, IngestOptions
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import PolarityMapper, to_pixel, to_us

log = logging.getLogger(__name__)

CHUNK_EVENTS = 1 << 22
UNIT_ATTRS = ("unit", "units", "time_unit", "t_unit")
UNIT_ALIASES = {
    "s": "s",
    "sec": "s",
    "seconds": "s",
    "ms": "ms",
    "us": "us",
    "µs": "us",
    "microseconds": "us",
    "ns": "ns",
    "nanoseconds": "ns",
}


@dataclass
class H5Layout:
    """Where the event arrays are: dataset names (or a single (N, 4) dataset) and the time unit."""

    name: str
    x: str
    y: str
    t: str
    p: str
    n: int
    unit: str | None
    unit_from: str
    columns: str | None = None  # v2e: the (N, 4) dataset


def _import_h5():
    import h5py
    import hdf5plugin  # noqa: F401  (registers Blosc/zstd/... filters before h5py opens a file)

    return h5py


def _attr_unit(path: Path, *objs) -> tuple[str | None, str]:
    for obj in objs:
        for key in UNIT_ATTRS:
            if key in obj.attrs:
                raw = obj.attrs[key]
                raw = raw.decode() if isinstance(raw, bytes) else str(raw)
                unit = UNIT_ALIASES.get(raw.strip().lower())
                if unit is None:
                    raise EigsError(path, f"attribute {obj.name}:{key} = {raw!r} is not a time unit (s, ms, us, ns)")
                return unit, f"attribute {obj.name}:{key}"
    return None, ""


def detect_layout(path: Path, f, time_unit: str | None) -> H5Layout:
    """Find the event arrays of an open HDF5 file ``f`` and decide the time unit (never from magnitudes)."""
    h5py = _import_h5()

    def ds(name: str) -> bool:
        return name in f and isinstance(f[name], h5py.Dataset)

    lay = None
    if all(ds(f"events/{k}") for k in "xytp"):
        lay = H5Layout("DSEC", "events/x", "events/y", "events/t", "events/p", 0, None, "")
        if f["events/t"].dtype.kind in "iu":
            lay.unit, lay.unit_from = "us", "DSEC layout (integer events/t is µs)"
    elif all(ds(f"events/{k}") for k in ("xs", "ys", "ts", "ps")):
        lay = H5Layout("Monash", "events/xs", "events/ys", "events/ts", "events/ps", 0, None, "")
    elif all(ds(k) for k in "xytp"):
        lay = H5Layout("flat", "x", "y", "t", "p", 0, None, "")
    elif ds("events") and f["events"].ndim == 2 and f["events"].shape[1] == 4:
        lay = H5Layout("v2e", "", "", "", "", 0, None, "", columns="events")
        if f["events"].dtype.kind in "iu":
            lay.unit, lay.unit_from = "us", "v2e layout (integer [t, x, y, p] with t in µs)"
    if lay is None:
        keys: list[str] = []
        f.visit(keys.append)
        raise EigsError(
            path,
            "no event arrays found (expected events/{x,y,t,p}, events/{xs,ys,ts,ps}, root x,y,t,p or an (N, 4) "
            f"'events' dataset); the file holds: {', '.join(keys[:12]) or 'nothing'}",
        )
    if lay.columns is None:
        arrays = [f[n] for n in (lay.x, lay.y, lay.t, lay.p)]
        for a in arrays:
            if a.ndim != 1:
                raise EigsError(path, f"{a.name} has shape {a.shape}, expected one dimension")
        lens = {a.name: a.shape[0] for a in arrays}
        if len(set(lens.values())) != 1:
            raise EigsError(path, "event arrays differ in length: " + ", ".join(f"{k} {v}" for k, v in lens.items()))
        lay.n = arrays[0].shape[0]
        tds = f[lay.t]
        attr_unit, attr_from = _attr_unit(path, tds, tds.parent, f)
    else:
        lay.n = f[lay.columns].shape[0]
        attr_unit, attr_from = _attr_unit(path, f[lay.columns], f)
    if attr_unit is not None:
        lay.unit, lay.unit_from = attr_unit, attr_from
    if time_unit is not None:
        if attr_unit is not None and attr_unit != time_unit:
            raise EigsError(path, f"--time-unit {time_unit} contradicts the file's {attr_from} = {attr_unit}")
        lay.unit, lay.unit_from = time_unit, "--time-unit"
    if lay.unit is None:
        raise EigsError(
            path,
            f"the time unit of the {lay.name} layout is not stated in the file; give --time-unit "
            + "|".join(TIME_UNITS),
        )
    return lay


def _size_attrs(path: Path, f) -> tuple[int | None, int | None]:
    for obj in (f, f["events"] if "events" in f else f):
        if "width" in obj.attrs and "height" in obj.attrs:
            try:
                w, h = int(obj.attrs["width"]), int(obj.attrs["height"])
            except (TypeError, ValueError):
                raise EigsError(path, "attributes width/height are not integers") from None
            if w <= 0 or h <= 0:
                raise EigsError(path, f"attributes width/height are {w}×{h}")
            return w, h
    return None, None


def _t_offset(path: Path, f, unit: str) -> int:
    if "t_offset" not in f:
        return 0
    try:
        v = np.asarray(f["t_offset"][()])
    except Exception as err:
        raise EigsError(path, f"cannot read t_offset ({err})") from None
    if v.size != 1 or v.dtype.kind not in "iu":
        raise EigsError(path, f"t_offset must be one integer (µs), got {v.dtype} {v.shape}")
    if unit != "us":
        raise EigsError(path, f"t_offset is in µs but events are in {unit}; cannot combine them")
    return int(v.reshape(()))


class _MsIndexCheck:
    """Checks DSEC ``ms_to_idx`` (ms_to_idx[k] = first index with t ≥ 1000·k, t relative to t_offset) chunk by chunk."""

    def __init__(self, path: Path, ms_to_idx: np.ndarray, n: int):
        self.path = path
        self.idx = ms_to_idx.astype(np.int64)
        if (
            self.idx.ndim != 1
            or np.any(np.diff(self.idx) < 0)
            or (self.idx.size and (self.idx[0] < 0 or self.idx[-1] > n))
        ):
            raise EigsError(path, "ms_to_idx is not a non-decreasing index into the events")
        self.prev_t: int | None = None

    def chunk(self, start: int, t_rel: np.ndarray) -> None:
        """``t_rel``: (n,) int64 relative µs of events [start, start + n)."""
        n = t_rel.shape[0]
        k = np.arange(self.idx.size, dtype=np.int64)
        # entries pointing inside this chunk: t[idx] >= 1000 k
        sel = (self.idx >= start) & (self.idx < start + n)
        bad = t_rel[self.idx[sel] - start] < 1000 * k[sel]
        # entries whose previous event is inside this chunk: t[idx - 1] < 1000 k
        sel2 = (self.idx - 1 >= start) & (self.idx - 1 < start + n)
        bad2 = t_rel[self.idx[sel2] - 1 - start] >= 1000 * k[sel2]
        if np.any(bad) or np.any(bad2):
            kk = int(k[sel][bad][0]) if np.any(bad) else int(k[sel2][bad2][0])
            raise EigsError(
                self.path,
                f"ms_to_idx[{kk}] = {self.idx[kk]} disagrees with events/t read as µs (corrupted, or t is not in µs)",
            )


def read_h5_events(
    path: Path, width: int, height: int, time_unit: str | None, chunk: int = CHUNK_EVENTS
) -> Iterator[EventChunk]:
    """Stream the events of an HDF5 file as converted chunks (x, y uint16; t int64 µs incl. t_offset; p int8 ±1)."""
    h5py = _import_h5()
    where = str(path)
    try:
        f = h5py.File(path, "r")
    except OSError as err:
        raise EigsError(path, f"not a readable HDF5 file ({err})") from None
    with f:
        lay = detect_layout(path, f, time_unit)
        offset = _t_offset(path, f, lay.unit or "us")
        ms_check = None
        if lay.name == "DSEC" and "ms_to_idx" in f:
            ms_check = _MsIndexCheck(path, f["ms_to_idx"][()], lay.n)
        polarity = PolarityMapper(where)
        last_t: int | None = None
        dsets = None if lay.columns else (f[lay.x], f[lay.y], f[lay.t], f[lay.p])
        for s in range(0, lay.n, chunk):
            e = min(lay.n, s + chunk)
            try:
                if dsets is None:
                    block = f[lay.columns][s:e]
                    t_raw, x_raw, y_raw, p_raw = block[:, 0], block[:, 1], block[:, 2], block[:, 3]
                else:
                    x_raw, y_raw, t_raw, p_raw = (d[s:e] for d in dsets)
            except (OSError, ValueError, RuntimeError) as err:
                raise EigsError(path, f"cannot read events {s}–{e}: truncated or corrupted ({err})") from None
            t = to_us(t_raw, lay.unit or "us", where, s)
            if ms_check is not None:
                ms_check.chunk(s, t)
            if offset:
                t += offset
            back = np.flatnonzero(t[1:] < t[:-1])
            if back.size or (last_t is not None and t[0] < last_t):
                i = s + (int(back[0]) + 1 if back.size else 0)
                raise EigsError(path, f"timestamps go backwards at event {i} (uint32 wrap-around or unsorted file)")
            last_t = int(t[-1])
            x = to_pixel(x_raw, width, "x", where, s)
            y = to_pixel(y_raw, height, "y", where, s)
            yield x, y, t, polarity(p_raw, s)


def read_sidecar(path: Path) -> tuple[np.ndarray | None, np.ndarray | None, list[Path]]:
    """Frames sidecar → (timestamps (V,) int64 µs or None, exposure (V, 2) int64 [start, end) or None, images)."""
    if not path.is_file():
        raise EigsError(path, "no such frames sidecar")
    rows: list[list[str]] = []
    ncols = None
    with open(path, errors="replace") as f:
        for lineno, line in enumerate(f, start=1):
            s = line.split("#", 1)[0].strip()
            if not s:
                continue
            parts = s.split()
            if ncols is None:
                ncols = len(parts)
                if ncols not in (2, 3):
                    raise EigsError(path, f"line {lineno}: expected 'start_us end_us image' or 't_us image'")
            if len(parts) != ncols:
                raise EigsError(path, f"line {lineno} has {len(parts)} fields, expected {ncols}")
            try:
                nums = [int(v) for v in parts[:-1]]
            except ValueError:
                raise EigsError(path, f"line {lineno}: times must be integers (µs)") from None
            rows.append([*map(str, nums), parts[-1]])
    if not rows:
        raise EigsError(path, "lists no frames")
    files = [path.parent / r[-1] for r in rows]
    nums = np.asarray([[int(v) for v in r[:-1]] for r in rows], dtype=np.int64)
    if ncols == 3:
        bad = np.flatnonzero(nums[:, 1] <= nums[:, 0])
        if bad.size:
            raise EigsError(path, f"frame {int(bad[0])} ends before it starts")
        back = np.flatnonzero(np.diff(nums[:, 0]) < 0)
        if back.size:
            raise EigsError(path, f"exposure starts go backwards at frame {int(back[0]) + 1}")
        return None, nums, files
    back = np.flatnonzero(np.diff(nums[:, 0]) < 0)
    if back.size:
        raise EigsError(path, f"timestamps go backwards at frame {int(back[0]) + 1}")
    return nums[:, 0], None, files


def open_h5_source(source: str, opts: IngestOptions) -> RawSource:
    """Open an HDF5 event file (and its optional frames sidecar) as a :class:`RawSource`."""
    from eigs.ingest.images import read_image, read_images
    from eigs.ingest.poses import read_groundtruth

    h5py = _import_h5()
    path = Path(source)
    if not path.is_file():
        raise EigsError(path, "no such file")
    try:
        with h5py.File(path, "r") as f:
            lay = detect_layout(path, f, opts.time_unit)
            width, height = _size_attrs(path, f)
    except OSError as err:
        raise EigsError(path, f"not a readable HDF5 file ({err})") from None
    src = RawSource(path=path, fmt="h5", name=path.stem, width=width, height=height, n_events=lay.n)
    src.notes.append(f"layout {lay.name}, time unit {lay.unit} from {lay.unit_from}")

    sidecar = Path(opts.frames) if opts.frames is not None else path.with_name(path.stem + ".frames.txt")
    if opts.frames is not None or sidecar.is_file():
        t, exposure, files = read_sidecar(sidecar)
        first = read_image(files[0])
        fh, fw = first.shape[:2]
        if opts.frames_homography is None:  # else the frames are another camera's, warped to the sensor later
            if width is not None and (fw, fh) != (width, height):
                raise EigsError(sidecar, f"frames are {fw}×{fh} but {path.name} says {width}×{height}")
            src.width, src.height = fw, fh
        src.frame_names = [Path(os.path.relpath(f, sidecar.parent)).as_posix() for f in files]
        src.n_frames = len(files)
        src.exposure_us = exposure
        src.frame_t_us = t if t is not None else None

        def load(idx: np.ndarray) -> np.ndarray:
            return read_images([files[i] for i in idx], desc="frames")

        src.load_frames = load
        src.notes.append(f"frames from {sidecar}")
    if opts.groundtruth is not None:
        src.trajectory = read_groundtruth(Path(opts.groundtruth))
    unit = opts.time_unit
    src.events = lambda w, h: read_h5_events(path, w, h, unit)
    return src
