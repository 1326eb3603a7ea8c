"""``eigs sfm``: camera poses for every latent frame (COLMAP or given), test cameras, accuracy report."""

from __future__ import annotations

import argparse

HELP = "camera poses of the EDI latent frames (COLMAP or given poses), test cameras and an accuracy report"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene file (scene.h5)")
    p.add_argument("edi", help="EDI artifact (b{B}/edi.h5)")
    p.add_argument("-o", "--output", required=True, help="output directory (sfm/), written atomically")
    p.add_argument("--latent-dir", help="latent PNGs (default: latent/ beside EDI.h5; written from it if absent)")
    p.add_argument(
        "--mode",
        choices=("auto", "colmap", "given"),
        default="auto",
        help="auto: given when the scene's latent poses are ground truth (and allowed), else colmap",
    )
    p.add_argument("--no-given", action="store_true", help="auto mode never picks given poses")
    p.add_argument("--matcher", choices=("auto", "exhaustive", "sequential"), default="auto",
                   help="auto: exhaustive up to 150 images, else sequential + spatial")  # fmt: skip
    p.add_argument("--global-mapping", action="store_true", help="global (GLOMAP) instead of incremental mapping")
    p.add_argument("--refine-intrinsics", action="store_true", help="let bundle adjustment refine the focal length")
    p.add_argument(
        "--min-registered-fraction",
        type=float,
        default=0.5,
        metavar="F",
        help="stop when fewer than this fraction of latent frames register (default 0.5)",
    )
    p.add_argument(
        "--no-interpolate", action="store_true", help="leave unregistered latents NaN instead of interpolating"
    )
    p.add_argument("--no-register-test", action="store_true", help="test cameras from the Sim(3) only")
    p.add_argument("--feature-scale", type=int, default=None, metavar="F", help="SIFT upsampling (default auto)")
    p.add_argument("--max-features", type=int, default=8192, metavar="N", help="SIFT features per image")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="auto", help="pycolmap device")
    p.add_argument("--seed", type=int, default=0, help="random seed of COLMAP's RANSAC and mapper")
    p.add_argument("--keep-work", action="store_true", help="keep the database and scratch files in OUT/work")
    p.add_argument("--no-plot", action="store_true", help="skip report.png")


def run(args: argparse.Namespace) -> int:
    import os

    from eigs.errors import EigsError
    from eigs.sfm.colmap import ColmapOptions
    from eigs.sfm.run import SfmConfig, run_sfm

    if not 0.0 <= args.min_registered_fraction <= 1.0:
        raise EigsError(None, f"--min-registered-fraction must lie in [0, 1], got {args.min_registered_fraction}")
    threads = args.threads or min(2, os.cpu_count() or 1)
    cfg = SfmConfig(
        mode=args.mode,
        allow_given=not args.no_given,
        min_registered_fraction=args.min_registered_fraction,
        interpolate_unregistered=not args.no_interpolate,
        register_test=not args.no_register_test,
        keep_work=args.keep_work,
        verbose=args.verbose,
        plot=not args.no_plot,
        colmap=ColmapOptions(
            matcher=args.matcher,
            global_mapping=args.global_mapping,
            refine_intrinsics=args.refine_intrinsics,
            feature_scale=args.feature_scale,
            max_num_features=args.max_features,
            num_threads=threads,
            device=args.device,
            seed=args.seed,
        ),
    )
    run_sfm(args.scene, args.edi, args.output, latent_dir=args.latent_dir, cfg=cfg)
    return 0
