"""User options of ``eigs ingest`` and their parsing (each bad value is an :class:`EigsError` naming the option)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.errors import EigsError
from eigs.util.options import Options

KEEP_EVENTS = ("exposures", "all")
TIME_UNITS = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}  # nanoseconds per unit
COMPRESSIONS = ("none", "gzip", "lzf")


@dataclass(frozen=True)
class IngestOptions(Options):
    """Options shared by every format; None means "not given" (the format's default applies). Checked when built
    (:meth:`problems`, each naming its flag): the CLI builds them from its flags (``eigs.ingest.cli``).

    ``intrinsics``: ``FX,FY,CX,CY[,K1,K2,P1,P2[,K3]]`` or a file holding those numbers (OpenCV convention:
    pixel centres at integer coordinates). ``sensor_size``: (width, height) px. ``exposure_us``: (start, end) µs
    offsets added to each frame timestamp. ``time_window``: [start, end) µs on the source clock.
    ``views``: a selection spec (:func:`parse_views`). ``time_unit``: one of :data:`TIME_UNITS` (HDF5 only).
    """

    name: str | None = None
    intrinsics: str | None = None
    sensor_size: tuple[int, int] | None = None
    exposure_us: tuple[int, int] | None = None
    keep_events: str | None = None
    views: str | None = None
    time_window: tuple[int, int] | None = None
    groundtruth: str | None = None
    undistort: bool = True
    time_unit: str | None = None
    frames: str | None = None
    frames_homography: str | None = None  # file: 3×3 frame→event pixel homography (eigs.ingest.sync)
    time_offset_us: int | tuple | None = None  # t_event = t_frame + N, or ("auto", (lo, hi) | None) (eigs.ingest.sync)
    camera_response: str | None = None
    contrast_threshold: float | None = None
    compression: str | None = None  # "none" is stored as None
    columns: str | None = None  # numpy: column order of a plain (N, K) array, e.g. "t,x,y,p"
    topics: tuple[str, ...] | None = None  # rosbag: ROLE=TOPIC choices (roles: events, image, camera_info, exposure)

    def __post_init__(self) -> None:
        if self.compression == "none":
            object.__setattr__(self, "compression", None)
        problems = self.problems()
        if problems:
            raise EigsError("ingest options", "; ".join(problems))

    def problems(self) -> list[str]:
        out = []
        if self.keep_events is not None and self.keep_events not in KEEP_EVENTS:
            out.append(f"--keep-events: must be one of {', '.join(KEEP_EVENTS)}, got {self.keep_events!r}")
        if self.time_unit is not None and self.time_unit not in TIME_UNITS:
            out.append(f"--time-unit: must be one of {', '.join(TIME_UNITS)}, got {self.time_unit!r}")
        if self.compression is not None and self.compression not in COMPRESSIONS:
            out.append(f"--compression: must be one of {', '.join(COMPRESSIONS)}, got {self.compression!r}")
        if self.exposure_us is not None and self.exposure_us[1] <= self.exposure_us[0]:
            out.append(f"--exposure-us: END must be after START, got {self.exposure_us[0]},{self.exposure_us[1]}")
        if self.time_window is not None and self.time_window[1] <= self.time_window[0]:
            out.append(f"--time-window: END must be after START, got {self.time_window[0]},{self.time_window[1]}")
        if self.contrast_threshold is not None and not (
            np.isfinite(self.contrast_threshold) and self.contrast_threshold > 0
        ):
            out.append(f"--contrast-threshold: must be a positive number, got {self.contrast_threshold}")
        return out

    def refuse(self, fmt: str, *names: str) -> None:
        """Raise when one of the options ``names`` (attribute names) was given to a format that has no use for it."""
        for n in names:
            value = getattr(self, n)
            given = value is not None if n != "undistort" else value is False
            if given:
                raise EigsError(f"--{n.replace('_', '-')}", f"does not apply to the {fmt} format")


def parse_int_pair(option: str, text: str) -> tuple[int, int]:
    """``"A,B"`` → (A, B) integers (µs); messages name ``option``."""
    parts = text.split(",")
    if len(parts) != 2:
        raise EigsError(option, f"expected START,END (integers, µs), got {text!r}")
    try:
        a, b = (int(s.strip()) for s in parts)
    except ValueError:
        raise EigsError(option, f"expected START,END (integers, µs), got {text!r}") from None
    return a, b


def parse_size(text: str) -> tuple[int, int]:
    """``"WxH"`` → (width, height) in pixels."""
    m = re.fullmatch(r"\s*(\d+)\s*[xX×,]\s*(\d+)\s*", text)
    if not m or int(m.group(1)) <= 0 or int(m.group(2)) <= 0:
        raise EigsError("--sensor-size", f"expected WIDTHxHEIGHT (positive integers), got {text!r}")
    return int(m.group(1)), int(m.group(2))


def opencv_to_K(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """OpenCV intrinsics (pixel centres at integer coordinates) → our K (centres at j + 0.5): (3, 3) float64."""
    return np.array([[fx, 0.0, cx + 0.5], [0.0, fy, cy + 0.5], [0.0, 0.0, 1.0]], dtype=np.float64)


def parse_calibration_numbers(values: list[float], where: str) -> tuple[np.ndarray, np.ndarray]:
    """``fx fy cx cy [k1 k2 p1 p2 [k3]]`` (OpenCV convention) → (K (3, 3) ours, distortion (5,) k1 k2 p1 p2 k3)."""
    if len(values) not in (4, 8, 9):
        raise EigsError(where, f"expected 4, 8 or 9 numbers (fx fy cx cy [k1 k2 p1 p2 [k3]]), got {len(values)}")
    v = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(v)):
        raise EigsError(where, "intrinsics contain NaN/Inf")
    if v[0] <= 0 or v[1] <= 0:
        raise EigsError(where, f"focal lengths must be positive, got fx={v[0]}, fy={v[1]}")
    dist = np.zeros(5)
    dist[: len(v) - 4] = v[4:]
    return opencv_to_K(*v[:4]), dist


def read_number_file(path: Path) -> list[float]:
    """All numbers of a small text file (whitespace or comma separated, ``#`` comments); EigsError if unreadable."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as err:
        raise EigsError(path, f"cannot read ({err.__class__.__name__})") from None
    tokens = re.split(r"[\s,]+", "\n".join(line.split("#", 1)[0] for line in text.splitlines()).strip())
    try:
        return [float(t) for t in tokens if t]
    except ValueError:
        raise EigsError(path, "holds something that is not a number") from None


def parse_intrinsics(spec: str) -> tuple[np.ndarray, np.ndarray]:
    """``--intrinsics``: a file path or ``FX,FY,CX,CY[,K1,K2,P1,P2[,K3]]`` (OpenCV convention) →
    (K (3, 3) float64 with pixel centres at j + 0.5, distortion (5,) float64)."""
    p = Path(spec)
    if p.is_file():
        return parse_calibration_numbers(read_number_file(p), str(p))
    if re.fullmatch(r"[\s\d.eE+\-,]+", spec):
        try:
            values = [float(s) for s in spec.split(",") if s.strip()]
        except ValueError:
            raise EigsError("--intrinsics", f"cannot parse {spec!r}") from None
        return parse_calibration_numbers(values, "--intrinsics")
    raise EigsError("--intrinsics", f"{spec!r} is neither a file nor FX,FY,CX,CY[,K1,K2,P1,P2[,K3]]")


def parse_views(spec: str, n: int) -> np.ndarray:
    """Select views from ``n``: comma-separated indices and Python slices (``0:30``, ``::10``, ``3,7,9``).

    Returns (M,) int64 strictly increasing indices into the source's views; EigsError when empty, out of
    range or not increasing.
    """
    picked: list[int] = []
    for item in spec.split(","):
        item = item.strip()
        if not item:
            continue
        try:
            if ":" in item:
                parts = [int(s) if s.strip() else None for s in item.split(":")]
                if len(parts) > 3:
                    raise ValueError
                picked.extend(range(n)[slice(*parts)])
            else:
                i = int(item)
                if not 0 <= i < n:
                    raise EigsError("--views", f"view {i} does not exist (the source has {n} views)")
                picked.append(i)
        except ValueError:
            raise EigsError("--views", f"cannot parse {item!r} (indices and slices like 0:30 or ::10)") from None
    idx = np.asarray(picked, dtype=np.int64)
    if idx.size == 0:
        raise EigsError("--views", f"{spec!r} selects no view (the source has {n} views)")
    if np.any(np.diff(idx) <= 0):
        raise EigsError("--views", f"{spec!r} must select views in increasing order without repeats")
    return idx
