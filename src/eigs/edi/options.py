"""Options of the ``edi`` stage: :class:`EdiOptions` holds every default and its accepted values (the config schema,
the rule and the CLI take theirs from here; built and checked as every stage's options are, ``eigs.util.options``).
No heavy imports: the CLI reads it for its help text. The `edi:` config section holds ``bins`` as a list of B, one
artifact each (the rule passes one B as ``--bins``)."""

from __future__ import annotations

from dataclasses import dataclass

from eigs.util.options import Options, choice, run_control

MODES = ("auto", "estimated", "e2nerf")
SCOPES = ("scene", "view")
DEFAULT_BINS = 4


@dataclass(frozen=True)
class EdiOptions(Options):
    """``mode``: auto (e2nerf for scenes ingested from E²NeRF layouts, else estimated), estimated or e2nerf;
    ``bins``: B, B + 1 latent frames per view (None: :data:`DEFAULT_BINS`, or the scene's own count when it is
    pre-binned); ``threshold``: contrast threshold in log units (None: estimated, or 0.3 in e2nerf mode);
    ``threshold_scope``: one estimate per scene or per view; ``mask_top``: hot-pixel/flicker mask, fraction of the
    busiest pixels eligible (0 disables); ``mask_factor``: they must also exceed this multiple of the mean events
    per pixel; ``per_pixel_threshold``: estimated mode, calibrate per-pixel ON/OFF thresholds from the events
    between exposures."""

    mode: str = choice("auto", MODES)
    bins: int | None = None
    threshold: float | None = None
    threshold_scope: str = choice("scene", SCOPES)
    mask_top: float = 0.01
    mask_factor: float = 8.0
    per_pixel_threshold: bool = True
    show_progress: bool = run_control(True)
