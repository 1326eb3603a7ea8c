"""In-memory form of a scene file (version 2, version 1 read too): what a data source provides, nothing derived.

Conventions (see docs/scene-format.md): camera-to-world 4×4 matrices in OpenCV axes (x right, y down,
z forward); intrinsics with pixel centres at (j + 0.5, i + 0.5); time in int64 microseconds; event polarity
±1; images uint8. Every part but the camera is optional: a stage that needs a part the scene lacks
refuses with a clear message (:meth:`Scene.require`).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from eigs.errors import EigsError

FORMAT_NAME = "eigs-scene"
FORMAT_VERSION = 2
READABLE_VERSIONS = (1, 2)  # version 2 added frames/t_us
CAMERA_RESPONSES = ("linear", "srgb", "unknown")
POSE_SOURCES = ("ground-truth", "estimated")
SHARP_KIND_BLUR_VIEW = 0  # ground truth at a training view's first latent time
SHARP_KIND_NOVEL_VIEW = 1  # ground truth at a held-out pose
SHARP_KINDS = {SHARP_KIND_BLUR_VIEW: "blur view", SHARP_KIND_NOVEL_VIEW: "novel view"}


@dataclass
class Camera:
    """Pinhole camera. ``K``: (3, 3) float64, pixel centres at (j+0.5, i+0.5); ``distortion``: (5,) float64
    OpenCV (k1, k2, p1, p2, k3), all zero when the frames and events are already undistorted."""

    K: np.ndarray
    width: int
    height: int
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(5))

    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.distortion != 0))


@dataclass
class Frames:
    """Motion-blurred frames. ``blurry``: (V, H, W, C) uint8, C ∈ {1, 3} (RGB);
    ``exposure_us``: (V, 2) int64 [start, end) per view, or None when the source does not know it;
    ``t_us``: (V,) int64 timestamp of each frame when there is no exposure window (the frame is then an instant),
    else None. At most one of the two is set. ``names``: (V,) the source's name of each frame (its image path as
    the source lists it, e.g. ``images/frame_000012.png``), or None; an existing COLMAP model's images are matched
    to the views by it (``sfm: mode: model``)."""

    blurry: np.ndarray
    exposure_us: np.ndarray | None = None
    t_us: np.ndarray | None = None
    names: list[str] | None = None

    @property
    def n_views(self) -> int:
        return int(self.blurry.shape[0])


@dataclass
class Events:
    """Raw events sorted by time. ``x``, ``y``: (N,) uint16 column/row; ``t``: (N,) int64 µs; ``p``: (N,) int8 ±1.
    ``view_index``: (V, 2) int64 half-open [start, stop) offsets of the events inside each view's exposure
    (None when exposures are unknown)."""

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    view_index: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def window(self, start: int, stop: int) -> Events:
        """Events ``[start, stop)`` by index (array views, no copy; no view index)."""
        return Events(self.x[start:stop], self.y[start:stop], self.t[start:stop], self.p[start:stop])

    def view(self, v: int) -> Events:
        """View ``v``'s exposure events: the window ``view_index[v]``."""
        if self.view_index is None:
            raise ValueError("these events have no view index")
        return self.window(*(int(k) for k in self.view_index[v]))

    def chunks(self, rows: int | None = None) -> Iterator[Events]:
        """The events in time order, in windows of ``rows`` (None: one window, all of them)."""
        n = len(self)
        step = max(int(rows or n), 1)
        for a in range(0, n, step):
            yield self.window(a, min(a + step, n))

    @staticmethod
    def empty() -> Events:
        return Events(
            np.zeros(0, np.uint16), np.zeros(0, np.uint16), np.zeros(0, np.int64), np.zeros(0, np.int8)
        )


class EventSource(Protocol):
    """Raw events read by windows: :class:`Events` in memory, or :class:`eigs.scene.file.EventFile` (a scene file's
    events, never all in memory). A stage that may meet a recording larger than memory takes one of these."""

    view_index: np.ndarray | None

    def __len__(self) -> int: ...

    def window(self, start: int, stop: int) -> Events: ...

    def chunks(self, rows: int | None = None) -> Iterator[Events]: ...


@dataclass
class BinnedEvents:
    """Pre-binned events for sources that keep no timestamps (E²NeRF's ``events.pt``).
    ``counts``: (V, B, H, W) int32 signed event counts; ``bin_edges_us``: (V, B + 1) int64, strictly increasing."""

    counts: np.ndarray
    bin_edges_us: np.ndarray

    @property
    def n_bins(self) -> int:
        return int(self.counts.shape[1])


@dataclass
class Poses:
    """Latent camera poses a source provides. ``latent_c2w``: (V, L, 4, 4) float64 camera-to-world (OpenCV axes);
    ``latent_t_us``: (V, L) int64; ``source``: ``ground-truth`` or ``estimated``."""

    latent_c2w: np.ndarray
    latent_t_us: np.ndarray
    source: str


@dataclass
class Trajectory:
    """Dense ground-truth camera trajectory: ``t_us`` (T,) int64 strictly increasing, ``c2w`` (T, 4, 4) float64."""

    t_us: np.ndarray
    c2w: np.ndarray


@dataclass
class SharpImages:
    """Ground-truth sharp images. ``images``: (S, H, W, C) uint8; ``c2w``: (S, 4, 4); ``t_us``: (S,) int64;
    ``kind``: (S,) uint8 (0 = blur view, 1 = novel view); ``view``: (S,) int64 training view of a blur view, −1
    for a novel view."""

    images: np.ndarray
    c2w: np.ndarray
    t_us: np.ndarray
    kind: np.ndarray
    view: np.ndarray


@dataclass
class Scene:
    """A whole scene file. ``background``: (C,) float in [0, 1]; ``contrast_threshold``: the event sensor's
    contrast threshold C when known (log-intensity units), else None."""

    name: str
    camera: Camera
    channels: int
    camera_response: str = "unknown"
    synthetic: bool = False
    background: np.ndarray | None = None
    contrast_threshold: float | None = None
    source: str = ""
    frames: Frames | None = None
    events: Events | None = None
    binned: BinnedEvents | None = None
    poses: Poses | None = None
    trajectory: Trajectory | None = None
    sharp: SharpImages | None = None

    @property
    def n_views(self) -> int:
        """Number of training views (blurry frames, else pose or bin groups); 0 when the scene has none."""
        for part, attr in ((self.frames, "blurry"), (self.poses, "latent_c2w"), (self.binned, "counts")):
            if part is not None:
                return int(getattr(part, attr).shape[0])
        return 0

    def require(self, *parts: str, path: str | None = None, hint: str = "") -> None:
        """Raise a clear :class:`EigsError` when one of ``parts`` (e.g. ``"frames"``, ``"events"``,
        ``"exposure"``, ``"poses"``, ``"sharp"``) is missing. ``hint`` tells the user how to add it."""
        missing = []
        for part in parts:
            if part == "exposure":
                ok = self.frames is not None and self.frames.exposure_us is not None
            elif part == "any-events":
                ok = self.events is not None or self.binned is not None
            else:
                ok = getattr(self, part) is not None
            if not ok:
                missing.append(part)
        if missing:
            extra = f" ({hint})" if hint else ""
            raise EigsError(path or self.name, f"the scene has no {', '.join(missing)}{extra}")
