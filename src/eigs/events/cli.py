"""``eigs edi SCENE.h5 -o edi.h5``: EDI latent sharp frames (binning, E²NeRF or estimated mode, latent PNGs)."""

from __future__ import annotations

import argparse

HELP = "EDI latent sharp frames from blurry frames and events (B + 1 per view), with their event integrals"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", help="scene file (.h5)")
    parser.add_argument("-o", "--output", required=True, metavar="edi.h5", help="EDI file to write")
    parser.add_argument(
        "--latent-dir", metavar="DIR", help="also write the latent frames as 8-bit PNGs vVVVV_kKK.png into DIR"
    )
    parser.add_argument(
        "--mode",
        choices=("auto", "estimated", "e2nerf"),
        default="auto",
        help="auto (default): e2nerf for scenes ingested from E²NeRF layouts, estimated otherwise",
    )
    parser.add_argument(
        "--bins", type=int, default=None, metavar="B",
        help="bins per exposure, B + 1 latent frames (default 4; pre-binned scenes: their own count)",
    )
    parser.add_argument(
        "--threshold", type=float, default=None, metavar="C",
        help="contrast threshold (log units) instead of the estimate (e2nerf mode: default 0.3)",
    )
    parser.add_argument(
        "--threshold-scope", choices=("scene", "view"), default="scene",
        help="estimate one threshold per scene (default) or one per view",
    )
    parser.add_argument(
        "--mask-top", type=float, default=0.01, metavar="F",
        help="hot-pixel/flicker mask: fraction of busiest pixels eligible (default 0.01; 0 disables)",
    )
    parser.add_argument(
        "--mask-factor", type=float, default=8.0, metavar="K",
        help="…and only those with more than K× the mean events per pixel (default 8)",
    )
    parser.add_argument(
        "--per-pixel-threshold", action=argparse.BooleanOptionalAction, default=True,
        help="estimated mode: calibrate per-pixel ON/OFF thresholds from the events between exposures (default on; "
        "falls back to the global threshold when the recording has too few gaps with events)",
    )


def run(args: argparse.Namespace) -> int:
    import logging
    import time

    from eigs.artifacts.edi import write_edi
    from eigs.events.pipeline import EdiOptions, compute_edi, write_latent_pngs
    from eigs.scene import read_scene

    log = logging.getLogger("eigs.events")
    t0 = time.perf_counter()
    scene = read_scene(args.scene)
    opts = EdiOptions(
        mode=args.mode,
        bins=args.bins,
        threshold=args.threshold,
        threshold_scope=args.threshold_scope,
        mask_top=args.mask_top,
        mask_factor=args.mask_factor,
        per_pixel_threshold=args.per_pixel_threshold,
    )
    result = compute_edi(scene, opts, path=args.scene)
    write_edi(result, args.output)
    if args.latent_dir:
        n = write_latent_pngs(result, args.latent_dir)
        log.info("wrote %d latent PNGs to %s", n, args.latent_dir)
    log.info(
        "%s: mode %s, B = %d, threshold %s (%s), %d sharp views, %.1f s",
        args.output, result.mode, result.n_bins,
        f"{result.threshold[0]:.4f}" if result.threshold_scope != "view" else "per view",
        result.threshold_scope, int(result.sharp.sum()), time.perf_counter() - t0,
    )
    return 0
