"""Which training methods need a scene's events: the one source of that fact, importable without torch (the workflow
reads it in rules/common.smk; the method classes read it into their ``needs_events`` attribute).

A method needs events when the loss of its recipe (its default options) reads what only events give the EDI
artifact: the event counts and thresholds (an event loss: ``eigs``, ``eigs-b``, ``e2gs``, ``besplat``,
``evagaussians``, ``e2nerf``) or the EDI latent frames as targets (``edi-3dgs``, ``edi-nerf``). On a scene configured
with ``events: false`` (``eigs edi --no-events``: every view passed through as sharp) such a run has nothing to
learn from, so the workflow does not schedule it there.

The other methods train on the blurry frames (or the ground truth: ``oracle``) and keep their jobs: ``3dgs``,
``nerf``, ``deblur-nerf``, and the blur-only deblurring methods ``eigs-minus``, ``deblurring-gs``,
``deblurring-gs+`` and ``bad-gaussians``. Those read the latent poses and EDI's sharp flags, not events; on a
frames-only scene every view is sharp, so with their default ``sharp_one_render`` they train one render per view as
``3dgs`` does (docs/methods.md). The fact is per method, not per run: options that switch an event term on or off
(``event_loss``, ``latent_weight``, ``blur_target: discrete``) do not change where a run is scheduled.
"""

from __future__ import annotations

EVENT_METHODS = frozenset({"eigs", "eigs-b", "e2gs", "besplat", "evagaussians", "edi-3dgs", "edi-nerf", "e2nerf"})


def needs_events(method: str) -> bool:
    """Whether ``method`` reads the scene's events (event counts or EDI latent frames)."""
    return method in EVENT_METHODS
