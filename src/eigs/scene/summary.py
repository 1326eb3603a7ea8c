"""A human-readable summary of a scene (printed by ingestion and ``eigs scene info``)."""

from __future__ import annotations

import numpy as np

from eigs.scene.model import SHARP_KIND_BLUR_VIEW, EventSource, Scene


def summarize(scene: Scene, dropped_events: int = 0, events: EventSource | None = None) -> str:
    """Views, events, event rate, time span, polarity balance, dropped events, ground truth. ``events``: the raw
    events when ``scene`` was read without them (read in chunks; default ``scene.events``)."""
    cam = scene.camera
    lines = [
        f"scene {scene.name!r}: {'synthetic' if scene.synthetic else 'real'}, {cam.width}×{cam.height}, "
        f"{scene.channels} channel(s), response {scene.camera_response}",
        f"  views: {scene.n_views}"
        + (
            ""
            if scene.frames is None
            else " blurry frames"
            + (
                ""
                if scene.frames.exposure_us is not None
                else " (instants: timestamps, no exposure windows)"
                if scene.frames.t_us is not None
                else " (exposure unknown)"
            )
        ),
    ]
    if scene.frames is not None and scene.frames.exposure_us is not None and scene.n_views:
        dur = np.diff(scene.frames.exposure_us, axis=1)[:, 0]
        lines.append(f"  exposure: median {np.median(dur) / 1e3:.3f} ms")
    ev = events if events is not None else scene.events
    if ev is not None and len(ev):
        pos, first, last = 0, None, 0
        for c in ev.chunks():
            pos += int(np.count_nonzero(c.p > 0))
            first = int(c.t[0]) if first is None else first
            last = int(c.t[-1])
        span = max(last - int(first or 0), 1)
        lines.append(
            f"  events: {len(ev):,} over {span / 1e6:.6f} s ({len(ev) / (span / 1e6):,.0f} ev/s), "
            f"t = [{first}, {last}] µs, positive {100.0 * pos / len(ev):.1f} %"
        )
    elif ev is not None:
        lines.append("  events: none")
    if scene.binned is not None:
        b = scene.binned
        lines.append(f"  binned events: {b.n_bins} bins per view, |sum| = {int(np.abs(b.counts).sum()):,}")
    if dropped_events:
        lines.append(f"  dropped events: {dropped_events:,}")
    if scene.poses is not None:
        lines.append(f"  poses: {scene.poses.latent_c2w.shape[1]} latent per view ({scene.poses.source})")
    gt = []
    if scene.trajectory is not None:
        gt.append(f"trajectory ({scene.trajectory.t_us.shape[0]} samples)")
    if scene.sharp is not None:
        nb = int(np.count_nonzero(scene.sharp.kind == SHARP_KIND_BLUR_VIEW))
        gt.append(f"sharp images ({nb} blur-view, {scene.sharp.kind.shape[0] - nb} novel-view)")
    lines.append("  ground truth: " + (", ".join(gt) if gt else "none"))
    if scene.contrast_threshold is not None:
        lines.append(f"  contrast threshold: {scene.contrast_threshold}")
    return "\n".join(lines)
