"""The scene file (HDF5, version 2; reads version 1): model, reader, writer, validation. See docs/scene-format.md."""

from eigs.scene.file import EventFile, SceneWriter, event_count, has_raw_events, read_events, read_scene, write_scene
from eigs.scene.model import (
    SHARP_KIND_BLUR_VIEW,
    SHARP_KIND_NOVEL_VIEW,
    BinnedEvents,
    Camera,
    Events,
    EventSource,
    Frames,
    Poses,
    Scene,
    SharpImages,
    Trajectory,
)
from eigs.scene.summary import summarize

__all__ = [
    "SHARP_KIND_BLUR_VIEW",
    "SHARP_KIND_NOVEL_VIEW",
    "BinnedEvents",
    "Camera",
    "EventFile",
    "EventSource",
    "Events",
    "Frames",
    "Poses",
    "Scene",
    "SceneWriter",
    "SharpImages",
    "Trajectory",
    "event_count",
    "has_raw_events",
    "read_events",
    "read_scene",
    "summarize",
    "write_scene",
]
