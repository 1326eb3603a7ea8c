"""Options of the ``edi`` stage: :class:`EdiOptions` holds every default (the config schema, the rule and the
CLI take theirs from here; see ``eigs.util.options``). No heavy imports: the CLI reads it for its help text."""

from __future__ import annotations

from dataclasses import dataclass, fields

MODES = ("auto", "estimated", "e2nerf")
SCOPES = ("scene", "view")
DEFAULT_BINS = 4


@dataclass
class EdiOptions:
    """``mode``: auto (e2nerf for scenes ingested from E²NeRF layouts, else estimated), estimated or e2nerf;
    ``bins``: B, B + 1 latent frames per view (None: :data:`DEFAULT_BINS`, or the scene's own count when it is
    pre-binned); ``threshold``: contrast threshold in log units (None: estimated, or 0.3 in e2nerf mode);
    ``threshold_scope``: one estimate per scene or per view; ``mask_top``: hot-pixel/flicker mask, fraction of the
    busiest pixels eligible (0 disables); ``mask_factor``: they must also exceed this multiple of the mean events
    per pixel; ``per_pixel_threshold``: estimated mode, calibrate per-pixel ON/OFF thresholds from the events
    between exposures."""

    mode: str = "auto"
    bins: int | None = None
    threshold: float | None = None
    threshold_scope: str = "scene"
    mask_top: float = 0.01
    mask_factor: float = 8.0
    per_pixel_threshold: bool = True
    show_progress: bool = True  # run control, not a config option


CONFIG_KEYS = tuple(f.name for f in fields(EdiOptions) if f.name != "show_progress")
CHOICES = {"mode": MODES, "threshold_scope": SCOPES}  # the keys of the `edi:` section that take one of a few values
