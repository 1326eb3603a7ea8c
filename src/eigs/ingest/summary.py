"""The summary ``eigs ingest`` prints: the scene summary plus what ingestion read, kept and dropped."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from eigs.scene.model import Scene
from eigs.scene.summary import summarize

if TYPE_CHECKING:
    from eigs.ingest.undistort import Undistorter


@dataclass
class EventStats:
    """Counts gathered while streaming (for the summary)."""

    read: int = 0
    kept: int = 0
    positive: int = 0
    t_first: int | None = None
    t_last: int | None = None
    outside_window: int = 0
    outside_exposures: int = 0
    undistort_dropped: int = 0
    keep_mode: str = "all"


def ingest_summary(
    header: Scene,
    stats: EventStats | None,
    calibration: str,
    undistorter: Undistorter | None,
    notes: list[str],
) -> str:
    """Text for a raw-event source: ``header`` is the scene without raw events; ``stats`` None when the source
    has no events (an RGB-only recording)."""
    lines = summarize(header).splitlines()
    extra: list[str] = []
    if stats is None:
        extra.append("  events: none in the source")
    else:
        if stats.kept and stats.t_first is not None and stats.t_last is not None:
            span = max(stats.t_last - stats.t_first, 1)
            extra.append(
                f"  events: {stats.kept:,} kept of {stats.read:,} read ({stats.keep_mode}) over {span / 1e6:.6f} s "
                f"({stats.kept / (span / 1e6):,.0f} ev/s), t = [{stats.t_first}, {stats.t_last}] µs, "
                f"positive {100.0 * stats.positive / stats.kept:.1f} %"
            )
        else:
            extra.append(f"  events: none kept of {stats.read:,} read ({stats.keep_mode})")
        dropped = [
            (stats.outside_window, "outside --time-window"),
            (stats.outside_exposures, "outside the views' exposures"),
            (stats.undistort_dropped, "outside the undistorted image"),
        ]
        text = ", ".join(f"{n:,} {why}" for n, why in dropped if n)
        extra.append(f"  dropped events: {text or 'none'}")
    cal = f"  calibration: {calibration}" if calibration else "  calibration: none"
    if undistorter is not None:
        cal += " — frames and events undistorted to the pinhole K"
    elif header.camera.has_distortion:
        cal += " — distortion kept (not undistorted)"
    extra.append(cal)
    extra.extend(f"  note: {n}" for n in notes)
    return "\n".join(insert_before_groundtruth(lines, extra))


def insert_before_groundtruth(lines: list[str], extra: list[str]) -> list[str]:
    """Insert ``extra`` lines before the summary's "ground truth" line (or at the end)."""
    at = next((i for i, line in enumerate(lines) if line.startswith("  ground truth:")), len(lines))
    return [*lines[:at], *extra, *lines[at:]]
