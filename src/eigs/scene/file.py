"""Reading and writing scene files (HDF5, version 2; version 1 is read too). The only module that knows the HDF5 paths.

Writes are atomic (temporary file + rename) and validated; reads are validated. Large event streams can be
written chunk by chunk with :class:`SceneWriter` and read by slices with :func:`read_events`.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from eigs.errors import H5_READ_ERRORS, EigsError
from eigs.scene.model import (
    FORMAT_NAME,
    FORMAT_VERSION,
    READABLE_VERSIONS,
    BinnedEvents,
    Camera,
    Events,
    Frames,
    Poses,
    Scene,
    SharpImages,
    Trajectory,
)
from eigs.scene.validate import (
    check_event_chunk,
    check_event_dtypes,
    check_view_index_sorted,
    validate,
    validate_header,
)
from eigs.util.atomic import atomic_path, ensure_space, nbytes_of

EVENT_CHUNK_ROWS = 1 << 20  # HDF5 chunk length for event arrays


def _open_read(path: str | os.PathLike) -> h5py.File:
    p = Path(path)
    if not p.exists():
        raise EigsError(p, "no such scene file")
    try:
        f = h5py.File(p, "r")
    except OSError as err:
        raise EigsError(p, f"not a readable HDF5 file ({err})") from None
    try:
        fmt = f.attrs.get("format")
        version = int(f.attrs.get("version", -1))
    except H5_READ_ERRORS as err:
        f.close()
        raise EigsError(p, f"corrupted scene file, unreadable header ({err})") from None
    if fmt != FORMAT_NAME:
        f.close()
        raise EigsError(p, f"not an eigs scene file (attribute format={fmt!r})")
    if version not in READABLE_VERSIONS:
        f.close()
        readable = ", ".join(map(str, READABLE_VERSIONS))
        raise EigsError(p, f"scene format version {version} is not supported (this eigs reads {readable})")
    return f


class SceneWriter:
    """Write a scene atomically; events may be appended in time-ordered chunks.

    >>> with SceneWriter("scene.h5", header) as w:   # header: a Scene whose ``events`` is None
    ...     w.append_events(x, y, t, p)               # any number of times
    ...     w.set_view_index(view_index)

    The header (everything but raw events) is validated on entry; each chunk is validated as it arrives
    (range, polarity, sortedness across chunks); the view index at the end. On any error nothing is left
    behind.

    A writer that learns the header only while it streams (the synth: frames are made view by view with their
    events) passes ``header=None`` and the ``camera`` (the events' range check), then :meth:`set_header` before
    the end; the header is validated then and must have that camera.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        header: Scene | None,
        *,
        compression: str | None = None,
        camera: Camera | None = None,
    ):
        if header is None and camera is None:
            raise ValueError("SceneWriter: give the header, or the camera and set_header() later")
        self.path = Path(path)
        self.header = header
        self.camera = header.camera if header is not None else camera
        self.compression = compression
        self._stack = contextlib.ExitStack()
        self._n = 0
        self._last_t: int | None = None
        self._view_index: np.ndarray | None = None
        self._has_events = False
        self._pending: list[tuple[np.ndarray, ...]] = []  # checked chunks not yet written
        self._pending_rows = 0

    # -- context management -------------------------------------------------------------------------
    def __enter__(self) -> SceneWriter:
        if self.header is not None:
            validate_header(str(self.path), self.header)
            ensure_space(self.path, nbytes_of(self.header))
        self._tmp = self._stack.enter_context(atomic_path(self.path))
        self._f = self._stack.enter_context(h5py.File(self._tmp, "w"))
        if self.header is not None:
            self._write_header()
        return self

    def set_header(self, header: Scene) -> None:
        """The header of a writer opened with ``header=None``: validated and written now; its camera must be the
        one the events were checked against."""
        if self.header is not None:
            raise RuntimeError("SceneWriter: the header is written already")
        validate_header(str(self.path), header)
        cam = header.camera
        if (cam.width, cam.height) != (self.camera.width, self.camera.height) or not np.array_equal(
            cam.K, self.camera.K
        ):
            raise EigsError(self.path, "the header's camera is not the one the events were written for")
        ensure_space(self.path, nbytes_of(header))
        self.header = header
        self._write_header()

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None:
            try:
                self._finish()
            except BaseException as err:
                self._stack.__exit__(type(err), err, err.__traceback__)
                raise
        return bool(self._stack.__exit__(exc_type, exc, tb))

    # -- parts ----------------------------------------------------------------------------------------
    def _ds(self, name: str, data: np.ndarray, **kw: Any) -> h5py.Dataset:
        if self.compression and data.size > 4096:
            kw.setdefault("compression", self.compression)
        return self._f.create_dataset(name, data=data, **kw)

    def _write_header(self) -> None:
        s, f = self.header, self._f
        f.attrs["format"] = FORMAT_NAME
        f.attrs["version"] = FORMAT_VERSION
        f.attrs["name"] = s.name
        f.attrs["synthetic"] = bool(s.synthetic)
        f.attrs["channels"] = int(s.channels)
        f.attrs["camera_response"] = s.camera_response
        f.attrs["source"] = s.source
        if s.background is not None:
            f.attrs["background"] = np.asarray(s.background, dtype=np.float64)
        if s.contrast_threshold is not None:
            f.attrs["contrast_threshold"] = float(s.contrast_threshold)
        cam = f.create_group("camera")
        cam.attrs["width"] = int(s.camera.width)
        cam.attrs["height"] = int(s.camera.height)
        cam.create_dataset("K", data=np.asarray(s.camera.K, dtype=np.float64))
        cam.create_dataset("distortion", data=np.asarray(s.camera.distortion, dtype=np.float64))
        if s.frames is not None:
            g = f.create_group("frames")
            v = s.frames.blurry.shape[0]
            self._ds("frames/blurry", s.frames.blurry, chunks=(1, *s.frames.blurry.shape[1:]) if v else None)
            g.attrs["exposure_known"] = s.frames.exposure_us is not None
            if s.frames.exposure_us is not None:
                g.create_dataset("exposure_us", data=s.frames.exposure_us)
            if s.frames.t_us is not None:
                g.create_dataset("t_us", data=s.frames.t_us)
            if s.frames.names is not None:
                g.create_dataset("names", data=list(s.frames.names), dtype=h5py.string_dtype())
        if s.binned is not None:
            self._ds("events/binned", s.binned.counts)
            self._f.create_dataset("events/bin_edges_us", data=s.binned.bin_edges_us)
        if s.poses is not None:
            g = f.create_group("poses")
            g.attrs["source"] = s.poses.source
            g.create_dataset("latent_c2w", data=np.asarray(s.poses.latent_c2w, dtype=np.float64))
            g.create_dataset("latent_t_us", data=s.poses.latent_t_us)
        if s.trajectory is not None:
            f.create_dataset("gt/trajectory/t_us", data=s.trajectory.t_us)
            f.create_dataset("gt/trajectory/c2w", data=np.asarray(s.trajectory.c2w, dtype=np.float64))
        if s.sharp is not None:
            sh = s.sharp
            self._ds("gt/sharp/images", sh.images)
            f.create_dataset("gt/sharp/c2w", data=np.asarray(sh.c2w, dtype=np.float64))
            f.create_dataset("gt/sharp/t_us", data=sh.t_us)
            f.create_dataset("gt/sharp/kind", data=sh.kind)
            f.create_dataset("gt/sharp/view", data=sh.view)

    def _event_datasets(self) -> None:
        if self._has_events:
            return
        for name, dt in (("x", np.uint16), ("y", np.uint16), ("t", np.int64), ("p", np.int8)):
            kw: dict[str, Any] = {"chunks": (EVENT_CHUNK_ROWS,), "maxshape": (None,)}
            if self.compression:
                kw["compression"] = self.compression
            self._f.create_dataset(f"events/{name}", shape=(0,), dtype=dt, **kw)
        self._has_events = True

    def append_events(self, x: np.ndarray, y: np.ndarray, t: np.ndarray, p: np.ndarray) -> None:
        """Append a time-ordered chunk: x, y (N,) uint16; t (N,) int64 µs ≥ the previous chunk's; p (N,) int8 ±1.
        Checked now; small chunks are gathered to a whole HDF5 chunk's rows before they are written (a write of a
        few events into a 2 MB chunk would read and write all of it)."""
        x, y = np.asarray(x, np.uint16), np.asarray(y, np.uint16)
        t, p = np.asarray(t, np.int64), np.asarray(p, np.int8)
        cam = self.camera
        self._last_t = check_event_chunk(str(self.path), x, y, t, p, cam.width, cam.height, self._last_t)
        self._event_datasets()
        if t.shape[0] >= EVENT_CHUNK_ROWS:
            self._flush()
            self._write((x, y, t, p))
            return
        self._pending.append(tuple(a.copy() for a in (x, y, t, p)))  # the caller may reuse its buffers
        self._pending_rows += t.shape[0]
        if self._pending_rows >= EVENT_CHUNK_ROWS:
            self._flush()

    def _flush(self) -> None:
        if self._pending:
            cols = tuple(np.concatenate(c) for c in zip(*self._pending, strict=True))
            self._pending, self._pending_rows = [], 0
            self._write(cols)

    def _write(self, cols: tuple[np.ndarray, ...]) -> None:
        ensure_space(self.path, nbytes_of(*cols))
        n, m = self._n, cols[2].shape[0]
        for name, a in zip(("x", "y", "t", "p"), cols, strict=True):
            ds = self._f[f"events/{name}"]
            ds.resize((n + m,))
            ds[n:] = a
        self._n = n + m

    def set_view_index(self, view_index: np.ndarray) -> None:
        """(V, 2) int64 [start, stop) offsets of each view's events (see :class:`Events`)."""
        self._view_index = np.asarray(view_index, dtype=np.int64)

    def _finish(self) -> None:
        if self.header is None:
            raise RuntimeError("SceneWriter: set_header() was not called")
        if self._view_index is not None and not self._has_events:
            self._event_datasets()
        self._flush()
        if self._has_events:
            if self._view_index is not None:
                exposure = self.header.frames.exposure_us if self.header.frames is not None else None
                n_views = self.header.n_views or self._view_index.shape[0]
                check_view_index_sorted(str(self.path), self._view_index, self._n, self._f["events/t"], exposure,
                                        n_views)
                self._f.create_dataset("events/view_index", data=self._view_index)
            self._f["events"].attrs["count"] = self._n


def write_scene(scene: Scene, path: str | os.PathLike, *, compression: str | None = None) -> None:
    """Validate ``scene`` and write it atomically to ``path``. ``compression``: None (default, fastest),
    ``"gzip"`` or ``"lzf"``. The writer validates the header on entry, the events as they are appended and the
    view index at the end, so nothing is checked twice."""
    header = Scene(**{**scene.__dict__, "events": None})
    if scene.events is not None:
        check_event_dtypes(str(path), scene.events)
    with SceneWriter(path, header, compression=compression) as w:
        if scene.events is not None:
            ev = scene.events
            w.append_events(ev.x, ev.y, ev.t, ev.p)  # creates the event datasets even when empty
            if ev.view_index is not None:
                w.set_view_index(ev.view_index)


def _opt(f: h5py.File, name: str) -> np.ndarray | None:
    return f[name][()] if name in f else None


def _read_header(f: h5py.File, binned: bool = True) -> Scene:
    cam_g = f["camera"]
    camera = Camera(
        K=cam_g["K"][()],
        width=int(cam_g.attrs["width"]),
        height=int(cam_g.attrs["height"]),
        distortion=cam_g["distortion"][()],
    )
    frames = None
    if "frames" in f:
        names = f["frames/names"].asstr()[()].tolist() if "frames/names" in f else None
        frames = Frames(
            blurry=f["frames/blurry"][()],
            exposure_us=_opt(f, "frames/exposure_us"),
            t_us=_opt(f, "frames/t_us"),
            names=names,
        )
    counts = None
    if binned and "events/binned" in f:
        counts = BinnedEvents(counts=f["events/binned"][()], bin_edges_us=f["events/bin_edges_us"][()])
    poses = None
    if "poses" in f:
        poses = Poses(f["poses/latent_c2w"][()], f["poses/latent_t_us"][()], str(f["poses"].attrs["source"]))
    trajectory = None
    if "gt/trajectory" in f:
        trajectory = Trajectory(f["gt/trajectory/t_us"][()], f["gt/trajectory/c2w"][()])
    sharp = None
    if "gt/sharp" in f:
        g = f["gt/sharp"]
        sharp = SharpImages(g["images"][()], g["c2w"][()], g["t_us"][()], g["kind"][()], g["view"][()])
    bg = f.attrs.get("background")
    ct = f.attrs.get("contrast_threshold")
    return Scene(
        name=str(f.attrs["name"]),
        camera=camera,
        channels=int(f.attrs["channels"]),
        camera_response=str(f.attrs["camera_response"]),
        synthetic=bool(f.attrs["synthetic"]),
        background=None if bg is None else np.asarray(bg, dtype=np.float64),
        contrast_threshold=None if ct is None else float(ct),
        source=str(f.attrs.get("source", "")),
        frames=frames,
        binned=counts,
        poses=poses,
        trajectory=trajectory,
        sharp=sharp,
    )


def read_scene(path: str | os.PathLike, *, events: bool = True, binned: bool = True) -> Scene:
    """Read and validate a scene file. ``events=False`` skips the raw event arrays (``scene.events`` is then
    None even when the file has events; use :func:`has_raw_events` / :func:`read_events`); ``binned=False`` skips
    the pre-binned counts (``scene.binned`` is then None)."""
    with _open_read(path) as f:
        try:
            scene = _read_header(f, binned)
            if events and "events/t" in f:
                scene.events = Events(
                    f["events/x"][()],
                    f["events/y"][()],
                    f["events/t"][()],
                    f["events/p"][()],
                    _opt(f, "events/view_index"),
                )
        except H5_READ_ERRORS as err:
            raise EigsError(path, f"corrupted or incomplete scene file ({err})") from None
    validate(str(path), scene)
    return scene


def has_raw_events(path: str | os.PathLike) -> bool:
    with _open_read(path) as f:
        return "events/t" in f


def read_events(path: str | os.PathLike, start: int = 0, stop: int | None = None) -> Events:
    """Read raw events ``[start, stop)`` (by index) without the rest of the file; ``view_index`` is included."""
    with _open_read(path) as f:
        if "events/t" not in f:
            raise EigsError(path, "the scene has no raw events")
        sl = slice(start, stop)
        try:
            return Events(
                f["events/x"][sl],
                f["events/y"][sl],
                f["events/t"][sl],
                f["events/p"][sl],
                _opt(f, "events/view_index"),
            )
        except H5_READ_ERRORS as err:
            raise EigsError(path, f"corrupted scene file, unreadable events ({err})") from None


class EventFile:
    """A scene file's raw events, read by windows (:class:`eigs.scene.model.EventSource`): memory holds a window,
    never the recording. ``view_index``: (V, 2) int64 or None; ``len()``: the event count.

    Checked as :func:`read_scene` checks them, by parts: on opening the arrays' dtypes and lengths and the view
    index (against the exposures, from its 2V boundary events); each window as it is read (range, polarity, time
    order; across the windows of :meth:`chunks` as well)."""

    READ_ROWS = 16 * EVENT_CHUNK_ROWS  # events per window of :meth:`chunks` (~200 MB)

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        p = str(path)
        with _open_read(path) as f:
            if "events/t" not in f:
                raise EigsError(path, "the scene has no raw events")
            try:
                ds = {k: f[f"events/{k}"] for k in ("x", "y", "t", "p")}
                n = int(ds["t"].shape[0])
                check_event_dtypes(p, Events(ds["x"], ds["y"], ds["t"], ds["p"]))  # datasets: read nothing
                for k in ("x", "y", "p"):
                    if ds[k].shape != (n,):
                        raise EigsError(path, f"events/{k} has {ds[k].shape[0]} entries but events/t has {n}")
                self._width = int(f["camera"].attrs["width"])
                self._height = int(f["camera"].attrs["height"])
                self.view_index = _opt(f, "events/view_index")
                if self.view_index is not None:
                    exposure = _opt(f, "frames/exposure_us")
                    check_view_index_sorted(p, self.view_index, n, ds["t"], exposure, self.view_index.shape[0])
            except H5_READ_ERRORS as err:
                raise EigsError(path, f"corrupted scene file, unreadable events ({err})") from None
        self._n = n

    def __len__(self) -> int:
        return self._n

    def _read(self, start: int, stop: int, last_t: int | None) -> tuple[Events, int | None]:
        ev = read_events(self.path, start, stop)
        ev.view_index = None
        last = check_event_chunk(str(self.path), ev.x, ev.y, ev.t, ev.p, self._width, self._height, last_t)
        return ev, last

    def window(self, start: int, stop: int) -> Events:
        return self._read(start, stop, None)[0]

    def chunks(self, rows: int | None = None) -> Iterator[Events]:
        step = max(int(rows or self.READ_ROWS), 1)
        last = None
        for a in range(0, self._n, step):
            ev, last = self._read(a, min(a + step, self._n), last)
            yield ev


def event_count(path: str | os.PathLike) -> int:
    with _open_read(path) as f:
        return int(f["events/t"].shape[0]) if "events/t" in f else 0
