"""ECD / v2e text recordings (``--format txt``).

A folder (or an event file inside one) holding any of:

- ``events.txt`` (ECD) or ``v2e-dvs-events.txt`` (v2e): ``t x y p`` per line, t in float seconds, x column, y row,
  p ∈ {0 = OFF, 1 = ON} (−1/+1 also accepted); an optional 5th column (v2e signal/noise flag) is ignored; lines
  starting with ``#`` are comments (v2e writes 6 or 7 header lines).
- ``images.txt``: ``t images/frame_<8 digits>.png`` (t in s, path relative to the folder). A folder with frames but
  no event file is an RGB-only recording.
- ``calib.txt``: ``fx fy cx cy k1 k2 p1 p2 k3`` (OpenCV convention, so cx, cy get +0.5).
- ``groundtruth.txt`` (or ``--groundtruth``): ``t tx ty tz qx qy qz qw`` (T_world_cam, t in s).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.ingest.options import IngestOptions, parse_calibration_numbers, read_number_file
from eigs.ingest.raw import EventChunk, RawSource
from eigs.ingest.timeconv import PolarityMapper, to_pixel, to_us

log = logging.getLogger(__name__)

EVENT_FILES = ("events.txt", "v2e-dvs-events.txt")
CHUNK_LINES = 2_000_000  # pandas' parser needs ~70 B per line of chunk


def _first_data_line(path: Path) -> tuple[int, list[str], str] | None:
    """(line number, fields, raw text) of the first non-comment, non-blank line; None without events."""
    try:
        with open(path, errors="strict") as f:
            for lineno, line in enumerate(f, start=1):
                s = line.split("#", 1)[0].strip()
                if s:
                    return lineno, s.split(), line.rstrip("\r\n")
    except UnicodeDecodeError:
        raise EigsError(path, "not a text file") from None
    return None


def _diagnose(path: Path, ncols: int, sep: str, fallback: str) -> EigsError:
    """Find the first malformed line of an event file (error path only) → an EigsError naming it."""
    try:
        with open(path, errors="replace") as f:
            for lineno, line in enumerate(f, start=1):
                s = line.split("#", 1)[0].strip()
                if not s:
                    continue
                parts = s.split()
                if sep == " " and line.rstrip("\r\n") != " ".join(parts):
                    return EigsError(path, f"line {lineno} separates fields differently from the first line")
                if len(parts) != ncols:
                    how = "truncated" if len(parts) < ncols else "too long"
                    return EigsError(path, f"line {lineno} has {len(parts)} fields, expected {ncols} ({how})")
                try:
                    t = float(parts[0])
                    ints = [int(v) for v in parts[1:4]]
                except ValueError:
                    return EigsError(path, f"line {lineno} is not 't x y p' numbers: {s[:60]!r}")
                if not np.isfinite(t):
                    return EigsError(path, f"line {lineno} has a NaN/Inf timestamp")
                del ints
    except OSError as err:
        return EigsError(path, f"cannot read ({err})")
    return EigsError(path, f"cannot parse the event file ({fallback})")


def _line_of_event(path: Path, index: int) -> int:
    """Line number (1-based) of event ``index`` (0-based, comments skipped). Error path only."""
    k = -1
    with open(path, errors="replace") as f:
        for lineno, line in enumerate(f, start=1):
            if line.split("#", 1)[0].strip():
                k += 1
                if k == index:
                    return lineno
    return -1


def read_event_text(path: Path, width: int, height: int, chunk: int = CHUNK_LINES) -> Iterator[EventChunk]:
    """Stream an ECD/v2e event file as converted chunks (x, y uint16; t int64 µs; p int8 ±1).

    Raises EigsError naming the line for malformed or truncated lines, NaN, coordinates outside the
    ``width`` × ``height`` sensor, bad polarity and timestamps that go backwards.
    """
    import pandas as pd

    first = _first_data_line(path)
    if first is None:
        return
    lineno, fields, line = first
    ncols = len(fields)
    # the C parser is twice as fast with a single-space separator; files with tabs or runs of spaces use \s+
    sep = " " if line == " ".join(fields) else r"\s+"
    if ncols not in (4, 5):
        raise EigsError(path, f"line {lineno} has {ncols} fields; expected 't x y p' (4, or 5 with a v2e flag)")
    names = ["t", "x", "y", "p", "flag"][:ncols]
    dtypes = {"t": np.float64, "x": np.int64, "y": np.int64, "p": np.int64, "flag": np.float64}
    where = str(path)
    polarity = PolarityMapper(where)
    offset = 0
    last_t: int | None = None
    try:
        reader = pd.read_csv(
            path,
            sep=sep,
            header=None,
            names=names,
            usecols=["t", "x", "y", "p"],
            comment="#",
            dtype=dtypes,
            chunksize=chunk,
            engine="c",
        )
        for df in reader:
            t_s = df["t"].to_numpy()
            n = t_s.shape[0]
            try:
                t = to_us(t_s, "s", where, offset)
                x = to_pixel(df["x"].to_numpy(), width, "x", where, offset)
                y = to_pixel(df["y"].to_numpy(), height, "y", where, offset)
                p = polarity(df["p"].to_numpy(), offset)
            except EigsError as err:
                raise _with_line(err, path) from None
            back = np.flatnonzero(t[1:] < t[:-1])
            if last_t is not None and n and t[0] < last_t:
                back = np.concatenate([[-1], back])
            if back.size:
                i = offset + int(back[0]) + 1
                raise EigsError(path, f"timestamps go backwards at line {_line_of_event(path, i)} (event {i})")
            if n:
                last_t = int(t[-1])
            yield x, y, t, p
            offset += n
    except (ValueError, pd.errors.ParserError) as err:
        raise _diagnose(path, ncols, sep, str(err).splitlines()[-1] if str(err) else type(err).__name__) from None
    except UnicodeDecodeError:
        raise EigsError(path, "not a text file") from None


def _with_line(err: EigsError, path: Path) -> EigsError:
    """Add the line number to a converter message that names ``event N``."""
    import re

    m = re.search(r"event (\d+)", err.problem)
    if not m:
        return err
    line = _line_of_event(path, int(m.group(1)))
    return EigsError(path, err.problem.replace(m.group(0), f"{m.group(0)} (line {line})"))


def read_images_txt(path: Path) -> tuple[np.ndarray, list[Path]]:
    """``images.txt`` → (t (V,) int64 µs non-decreasing, image paths relative to its folder)."""
    ts: list[str] = []
    files: list[Path] = []
    with open(path, errors="replace") as f:
        for lineno, line in enumerate(f, start=1):
            s = line.split("#", 1)[0].strip()
            if not s:
                continue
            parts = s.split()
            if len(parts) != 2:
                raise EigsError(path, f"line {lineno} has {len(parts)} fields, expected 't image_path'")
            ts.append(parts[0])
            files.append(path.parent / parts[1])
    try:
        t_s = np.asarray([float(v) for v in ts], dtype=np.float64)
    except ValueError:
        raise EigsError(path, "a timestamp is not a number") from None
    t = to_us(t_s, "s", str(path))
    back = np.flatnonzero(np.diff(t) < 0)
    if back.size:
        raise EigsError(path, f"timestamps go backwards at frame {int(back[0]) + 1}")
    return t, files


def open_text_source(source: str, opts: IngestOptions) -> RawSource:
    """Open an ECD/v2e text recording (folder or event file) as a :class:`RawSource`."""
    from eigs.ingest.images import read_image, read_images
    from eigs.ingest.poses import read_groundtruth

    opts.refuse("txt", "time_unit", "frames")
    p = Path(source)
    if not p.exists():
        raise EigsError(p, "no such file or folder")
    if p.is_file():
        folder, ev_file = p.parent, p
    else:
        folder = p
        ev_file = next((folder / n for n in EVENT_FILES if (folder / n).is_file()), None)
    images_txt = folder / "images.txt"
    if ev_file is None and not images_txt.is_file():
        raise EigsError(p, f"no event file ({' or '.join(EVENT_FILES)}) and no images.txt")
    src = RawSource(path=ev_file if p.is_file() else folder, fmt="txt", name=(p.stem if p.is_file() else p.name))

    calib = folder / "calib.txt"
    if calib.is_file() and opts.intrinsics is None:
        src.K, src.distortion = parse_calibration_numbers(read_number_file(calib), str(calib))
        src.calibration = str(calib)

    if images_txt.is_file():
        t, files = read_images_txt(images_txt)
        if not files:
            raise EigsError(images_txt, "lists no frames")
        first = read_image(files[0])
        if opts.frames_homography is None:  # else another camera's frames, warped to the sensor later
            src.height, src.width = first.shape[:2]
        src.n_frames = len(files)
        src.frame_names = [Path(os.path.relpath(f, images_txt.parent)).as_posix() for f in files]
        src.frame_t_us = t

        def load(idx: np.ndarray) -> np.ndarray:
            return read_images([files[i] for i in idx], desc="frames")

        src.load_frames = load

    gt = Path(opts.groundtruth) if opts.groundtruth is not None else folder / "groundtruth.txt"
    if opts.groundtruth is not None or gt.is_file():
        src.trajectory = read_groundtruth(gt)

    if ev_file is not None:
        path = ev_file
        src.events = lambda w, h: read_event_text(path, w, h)
    return src
