"""``eigs edi SCENE.h5 -o edi.h5``: EDI latent sharp frames (binning, E²NeRF or estimated mode, latent PNGs).

Options: every default lives in :class:`eigs.edi.options.EdiOptions`; ``--config JSON`` (the rule's ``edi:``
config section) sets any of them, and a flag given here wins over it. ``--no-events`` (not an EDI option: the
workflow's ``edi_frames`` job for a scene configured with ``events: false``) passes every view through as sharp
without reading the events.
"""

from __future__ import annotations

import argparse

from eigs.edi.options import DEFAULT_BINS, MODES, SCOPES, EdiOptions

HELP = "EDI latent sharp frames from blurry frames and events (B + 1 per view), with their event integrals"
_D = EdiOptions()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene file (.h5)")
    parser.add_argument("-o", "--output", required=True, metavar="edi.h5", help="EDI file to write")
    parser.add_argument(
        "--latent-dir", metavar="DIR", help="also write the latent frames as 8-bit PNGs vVVVV_kKK.png into DIR"
    )
    parser.add_argument(
        "--config", metavar="JSON", help="options as one JSON object (keys as in the `edi:` config section)"
    )
    parser.add_argument(
        "--no-events", dest="events", action="store_false",
        help="do not use the scene's events (a frames-only recording, or none wanted; the workflow's edi_frames job "
        "for `events: false` scenes): every view is passed through as sharp, as for a scene without events, and "
        "the event arrays are not read; the same edi.h5 and latent PNGs",
    )  # fmt: skip
    parser.add_argument(
        "--mode", choices=MODES,
        help=f"auto: e2nerf for scenes ingested from E²NeRF layouts, estimated otherwise (default {_D.mode})",
    )
    parser.add_argument(
        "--bins", type=int, metavar="B",
        help=f"bins per exposure, B + 1 latent frames (default {DEFAULT_BINS}; pre-binned scenes: their own count)",
    )
    parser.add_argument(
        "--threshold", type=float, metavar="C",
        help="contrast threshold (log units) instead of the estimate (e2nerf mode: default 0.3)",
    )
    parser.add_argument(
        "--threshold-scope", choices=SCOPES,
        help=f"estimate one threshold per scene or one per view (default {_D.threshold_scope})",
    )
    parser.add_argument(
        "--mask-top", type=float, metavar="F",
        help=f"hot-pixel/flicker mask: fraction of busiest pixels eligible (default {_D.mask_top}; 0 disables)",
    )
    parser.add_argument(
        "--mask-factor", type=float, metavar="K",
        help=f"…and only those with more than K× the mean events per pixel (default {_D.mask_factor})",
    )
    parser.add_argument(
        "--per-pixel-threshold", action=argparse.BooleanOptionalAction, default=None,
        help="estimated mode: calibrate per-pixel ON/OFF thresholds from the events between exposures (default "
        f"{'on' if _D.per_pixel_threshold else 'off'}; falls back to the global threshold when the recording has "
        "too few gaps with events)",
    )  # fmt: skip


def options(args: argparse.Namespace) -> EdiOptions:
    """:class:`EdiOptions` from the defaults, ``--config`` and the flags given (in that order), checked."""
    from eigs.util.options import accepted, flags, from_command_line

    return from_command_line(EdiOptions, args.config, flags(args, accepted(EdiOptions)))


def run(args: argparse.Namespace) -> int:
    import logging
    import time
    from pathlib import Path

    from eigs.artifacts.edi import write_edi, write_latent_pngs
    from eigs.edi.pipeline import compute_edi
    from eigs.scene import EventFile, has_raw_events, read_scene

    log = logging.getLogger("eigs.edi")
    t0 = time.perf_counter()
    opts = options(args)
    # the raw events are read a view's window at a time (eigs.edi.pipeline), never all at once
    scene = read_scene(args.scene, events=False, binned=args.events)
    source = EventFile(args.scene) if args.events and has_raw_events(args.scene) else None
    result = compute_edi(scene, opts, path=args.scene, events=args.events, source=source)
    write_edi(result, args.output)
    if args.latent_dir:
        try:
            n = write_latent_pngs(result.latent, args.latent_dir)
        except BaseException:  # both artifacts or neither (each write is atomic)
            Path(args.output).unlink(missing_ok=True)
            raise
        log.info("wrote %d latent PNGs to %s", n, args.latent_dir)
    log.info(
        "%s: mode %s, B = %d, threshold %s (%s), %d sharp views, %.1f s",
        args.output, result.mode, result.n_bins,
        f"{result.threshold[0]:.4f}" if result.threshold_scope != "view" else "per view",
        result.threshold_scope, int(result.sharp.sum()), time.perf_counter() - t0,
    )
    return 0
