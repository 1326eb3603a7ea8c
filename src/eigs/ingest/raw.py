"""Streaming ingestion of sources with raw (timestamped) events: h5, txt, aedat4.

A format module opens its source as a :class:`RawSource` (metadata, a frame loader, an event-chunk iterator
already converted to our units); :func:`ingest_raw` applies the user's options in a fixed order and streams the
events into :class:`eigs.scene.SceneWriter`:

1. camera: the source's calibration or ``--intrinsics``; sensor size from the source or ``--sensor-size``;
2. exposures: the source's, or frame timestamp + ``--exposure-us`` offsets;
3. views: ``--views`` then ``--time-window`` (a view is kept when its exposure lies inside the window, or its
   timestamp when exposures are unknown);
4. frames: loaded for the kept views only, undistorted when the calibration has distortion;
5. events, chunk by chunk: time window, then the kept views' exposures (``--keep-events exposures``), then
   undistortion; the view index counts kept events with exposure start ≤ t < end.

Memory: one chunk of input plus the frames; the writer's final view-index check reads the kept timestamps.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import IngestOptions, parse_intrinsics, parse_views
from eigs.ingest.summary import EventStats, ingest_summary
from eigs.scene.model import Camera, Frames, Scene, Trajectory

log = logging.getLogger(__name__)

EventChunk = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # x, y uint16; t int64 µs; p int8 ±1


@dataclass
class RawSource:
    """What a raw-event format module provides.

    ``frame_t_us``: (V,) int64 frame timestamps or None; ``exposure_us``: (V, 2) int64 [start, end) or None;
    ``load_frames(indices)``: (M,) int64 source view indices → (M, H, W, C) uint8; ``events()``: iterator of
    time-ordered chunks (x, y uint16 sensor pixels checked against the sensor size; t int64 µs; p int8 ±1);
    ``n_events``: total for the progress bar (None when unknown). ``K`` uses our pixel-centre convention.
    With ``--frames-homography`` the frames may have another size than the sensor (they are warped onto it).
    """

    path: Path
    fmt: str
    name: str
    width: int | None = None
    height: int | None = None
    K: np.ndarray | None = None
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))
    calibration: str = ""
    n_frames: int = 0
    frame_t_us: np.ndarray | None = None
    exposure_us: np.ndarray | None = None
    load_frames: Callable[[np.ndarray], np.ndarray] | None = None
    events: Callable[[int, int], Iterator[EventChunk]] | None = None
    n_events: int | None = None
    trajectory: Trajectory | None = None
    frame_names: list[str] | None = None  # (V,) the source's name of each frame (image path as listed)
    notes: list[str] = field(default_factory=list)


def merge_windows(exposure_us: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(V, 2) [start, end) windows → disjoint sorted union as (starts (M,), ends (M,)) int64."""
    order = np.argsort(exposure_us[:, 0], kind="stable")
    s, e = exposure_us[order, 0], exposure_us[order, 1]
    nonempty = e > s
    s, e = s[nonempty], e[nonempty]
    if s.size == 0:
        return s, e
    run_end = np.maximum.accumulate(e)
    new = np.ones(s.size, dtype=bool)
    new[1:] = s[1:] > run_end[:-1]
    starts = s[new]
    group = np.cumsum(new) - 1
    ends = np.zeros(starts.size, dtype=np.int64)
    np.maximum.at(ends, group, e)
    return starts, ends


def in_windows(t: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(N,) int64 µs → (N,) bool: inside one of the disjoint sorted [start, end) windows."""
    if starts.size == 0:
        return np.zeros(t.shape, dtype=bool)
    i = np.searchsorted(ends, t, side="right")
    ok = i < starts.size
    ok[ok] = starts[i[ok]] <= t[ok]
    return ok


def _camera(src: RawSource, opts: IngestOptions) -> tuple[np.ndarray, np.ndarray, int, int, str]:
    """(K, distortion, width, height, description) after ``--intrinsics`` / ``--sensor-size``."""
    w, h = src.width, src.height
    if opts.sensor_size is not None:
        sw, sh = opts.sensor_size
        if w is not None and (w, h) != (sw, sh):
            raise EigsError(src.path, f"the source is {w}×{h} but --sensor-size says {sw}×{sh}")
        w, h = sw, sh
    if w is None or h is None:
        raise EigsError(src.path, "the source does not state the sensor size; give --sensor-size WIDTHxHEIGHT")
    if opts.intrinsics is not None:
        K, dist = parse_intrinsics(opts.intrinsics)
        desc = f"--intrinsics {opts.intrinsics}"
    elif src.K is not None:
        K, dist, desc = src.K, src.distortion, src.calibration
    else:
        raise EigsError(
            src.path,
            "the source has no camera calibration; give --intrinsics FX,FY,CX,CY[,K1,K2,P1,P2,K3] or a calib file",
        )
    return K, dist, int(w), int(h), desc


def _views(src: RawSource, opts: IngestOptions, exposure: np.ndarray | None) -> np.ndarray:
    """Source view indices kept by ``--views`` and ``--time-window`` → (M,) int64."""
    idx = np.arange(src.n_frames, dtype=np.int64)
    if opts.views is not None:
        if src.n_frames == 0:
            raise EigsError("--views", f"{src.path} has no frames to select")
        idx = parse_views(opts.views, src.n_frames)
    if opts.time_window is not None and idx.size:
        w0, w1 = opts.time_window
        if exposure is not None:
            inside = (exposure[idx, 0] >= w0) & (exposure[idx, 1] <= w1)
        else:
            assert src.frame_t_us is not None
            inside = (src.frame_t_us[idx] >= w0) & (src.frame_t_us[idx] < w1)
        idx = idx[inside]
        if idx.size == 0:
            raise EigsError("--time-window", f"no frame of {src.path} lies inside [{w0}, {w1}) µs")
    return idx


def _apply_time_offset(
    src: RawSource, opts: IngestOptions, exposure: np.ndarray | None, homography: np.ndarray | None, width: int,
    height: int,
) -> np.ndarray | None:  # fmt: skip
    """Move the frame times onto the event clock (t_event = t_frame + offset): ``src.frame_t_us`` in place, the
    exposures returned. ``--time-offset-us auto`` estimates the offset first (:mod:`eigs.ingest.sync`) from the
    frames selected by ``--views`` (all by default) and one extra pass over the events."""
    from eigs.ingest import sync

    if src.frame_t_us is None and exposure is None:
        raise EigsError("--time-offset-us", f"{src.path} has no frame times to move")
    off = opts.time_offset_us
    if isinstance(off, tuple):
        if src.events is None or src.load_frames is None:
            raise EigsError("--time-offset-us", f"auto needs frames and events; {src.path} lacks one of them")
        idx = np.arange(src.n_frames) if opts.views is None else parse_views(opts.views, src.n_frames)
        frames = src.load_frames(idx)
        if homography is not None:
            import cv2

            h, w = frames.shape[1:3]
            frames, _ = sync.warp_frames(frames, homography, width, height)
            mask = cv2.warpPerspective(np.full((h, w), 255, np.uint8), homography, (width, height),
                                       flags=cv2.INTER_NEAREST) > 0  # fmt: skip
        elif frames.shape[1:3] != (height, width):
            raise EigsError("--time-offset-us", "auto compares frames and events pixel by pixel: frames of another "
                            "size than the sensor need --frames-homography")  # fmt: skip
        else:
            mask = np.ones((height, width), bool)
        if exposure is not None:
            mid = (exposure[idx, 0] + exposure[idx, 1]) // 2
            length = float(np.median(exposure[idx, 1] - exposure[idx, 0]))
        else:
            mid, length = src.frame_t_us[idx], None
        ev = sync.gather_events(src.events(width, height), width, height, sync.sample_pixels(mask), src.n_events)
        est = sync.estimate_time_offset(frames, mid, ev, exposure_len_us=length, search_us=off[1], where=src.path)
        log.info(est.describe())
        src.notes.append(est.describe())
        off = est.offset_us
    else:
        src.notes.append(f"frame times moved onto the event clock by --time-offset-us {off}")
    if src.frame_t_us is not None:
        src.frame_t_us = src.frame_t_us + int(off)
    return None if exposure is None else exposure + int(off)


def ingest_raw(src: RawSource, out: str | Path, opts: IngestOptions) -> str:
    """Write the scene of ``src`` to ``out`` (atomically) following ``opts``; returns the summary text."""
    from eigs.ingest.undistort import Undistorter
    from eigs.scene import SceneWriter
    from eigs.util.progress import progress

    K, dist, width, height, calib_desc = _camera(src, opts)
    homography = None
    if opts.frames_homography is not None:
        from eigs.ingest.sync import parse_homography

        homography = parse_homography(opts.frames_homography)
        src.notes.append(f"frames warped onto the {width}×{height} event sensor by {opts.frames_homography}")

    # exposures
    exposure = src.exposure_us
    if opts.exposure_us is not None:
        if exposure is not None:
            raise EigsError("--exposure-us", f"{src.path} already states exposure times")
        if src.frame_t_us is None:
            raise EigsError("--exposure-us", f"{src.path} has no frame timestamps to add the offsets to")
        exposure = src.frame_t_us[:, None] + np.asarray(opts.exposure_us, dtype=np.int64)[None, :]

    if opts.time_offset_us is not None:
        exposure = _apply_time_offset(src, opts, exposure, homography, width, height)
    views = _views(src, opts, exposure)
    frame_t_kept = None
    if exposure is None and views.size:
        if src.frame_t_us is not None:
            frame_t_kept = np.ascontiguousarray(src.frame_t_us[views], dtype=np.int64)
            src.notes.append(
                "frames are instants (timestamps kept, no exposure windows: EDI passes them through); "
                "--exposure-us START,END gives them exposure windows"
            )
        else:
            src.notes.append("frames have neither timestamps nor exposure windows")
    exposure_kept = None if exposure is None else np.ascontiguousarray(exposure[views])

    keep_mode = opts.keep_events or ("exposures" if exposure_kept is not None else "all")
    if keep_mode == "exposures" and exposure_kept is None and src.events is not None:
        raise EigsError(
            src.path,
            "--keep-events exposures needs exposure times, which the source lacks; give --exposure-us START,END "
            "or --keep-events all",
        )

    undistorter = None
    has_dist = bool(np.any(dist != 0))
    if has_dist and opts.undistort:
        undistorter = Undistorter(K, dist, width, height)
        cam = Camera(K=K, width=width, height=height, distortion=np.zeros(5))
    else:
        cam = Camera(K=K, width=width, height=height, distortion=np.asarray(dist, np.float64))

    frames = None
    channels = 1
    if views.size:
        assert src.load_frames is not None
        blurry = src.load_frames(views)
        if homography is not None:
            from eigs.ingest.sync import warp_frames

            blurry, coverage = warp_frames(blurry, homography, width, height)
            if coverage == 0:
                raise EigsError(opts.frames_homography, "the homography maps the frames outside the event sensor")
            src.notes.append(f"the warped frames cover {100 * coverage:.1f} % of the event sensor (black elsewhere)")
        if blurry.shape[1:3] != (height, width):
            raise EigsError(
                src.path, f"frames are {blurry.shape[2]}×{blurry.shape[1]} but the sensor is {width}×{height}"
            )
        channels = int(blurry.shape[3])
        if undistorter is not None:
            blurry = undistorter.frames(blurry)
        names = None if src.frame_names is None else [src.frame_names[i] for i in views]
        frames = Frames(blurry=blurry, exposure_us=exposure_kept, t_us=frame_t_kept, names=names)

    header = Scene(
        name=opts.name or src.name,
        camera=cam,
        channels=channels,
        camera_response=opts.camera_response or "unknown",
        synthetic=False,
        background=None,
        contrast_threshold=opts.contrast_threshold,
        source=f"{src.fmt}:{src.path}",
        frames=frames,
        trajectory=src.trajectory,
    )

    stats = EventStats(keep_mode=keep_mode)
    if exposure_kept is not None:
        starts, ends = merge_windows(exposure_kept)
        bounds = exposure_kept.ravel()
        counts = np.zeros(bounds.shape, dtype=np.int64)
    with SceneWriter(out, header, compression=opts.compression) as w:
        if src.events is not None:
            chunks = src.events(width, height)
            for x, y, t, p in progress(chunks, desc=f"events {src.path.name}", unit="chunk"):
                stats.read += t.shape[0]
                keep = None
                if opts.time_window is not None:
                    keep = (t >= opts.time_window[0]) & (t < opts.time_window[1])
                    stats.outside_window += int(t.shape[0] - np.count_nonzero(keep))
                if keep_mode == "exposures":
                    inside = in_windows(t, starts, ends)
                    if keep is not None:
                        stats.outside_exposures += int(np.count_nonzero(keep & ~inside))
                        keep &= inside
                    else:
                        stats.outside_exposures += int(t.shape[0] - np.count_nonzero(inside))
                        keep = inside
                if keep is not None:
                    x, y, t, p = x[keep], y[keep], t[keep], p[keep]
                if undistorter is not None:
                    ok, x, y = undistorter.events(x, y)
                    stats.undistort_dropped += int(ok.shape[0] - x.shape[0])
                    t, p = t[ok], p[ok]
                if t.shape[0] == 0:
                    continue
                w.append_events(x, y, t, p)
                if exposure_kept is not None:
                    counts += np.searchsorted(t, bounds, side="left")
                stats.kept += t.shape[0]
                stats.positive += int(np.count_nonzero(p > 0))
                if stats.t_first is None:
                    stats.t_first = int(t[0])
                stats.t_last = int(t[-1])
            if exposure_kept is not None:
                w.set_view_index(counts.reshape(-1, 2))
            elif stats.kept == 0:  # the source has events but none was kept: write the empty arrays
                e = np.zeros(0, np.int64)
                w.append_events(e.astype(np.uint16), e.astype(np.uint16), e, e.astype(np.int8))
    return ingest_summary(header, stats if src.events is not None else None, calib_desc, undistorter, src.notes)
