"""``eigs sfm``: camera poses for every latent frame (COLMAP or given), test cameras, accuracy report.

Options: every default lives in :class:`eigs.sfm.options.SfmConfig` / :class:`~eigs.sfm.options.ColmapOptions`;
``--config JSON`` (the rule's ``sfm:`` config section) sets any of them, and a flag given here wins over it.
"""

from __future__ import annotations

import argparse

from eigs.sfm.options import DEVICES, MATCHERS, MODES, ColmapOptions, SfmConfig

HELP = "camera poses of the EDI latent frames (COLMAP or given poses), test cameras and an accuracy report"
_D, _C = SfmConfig(), ColmapOptions()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene file (scene.h5)")
    p.add_argument("edi", help="EDI artifact (b{B}/edi.h5)")
    p.add_argument("-o", "--output", required=True, help="output directory (sfm/), written atomically")
    p.add_argument("--latent-dir", help="latent PNGs (default: latent/ beside EDI.h5; written from it if absent)")
    p.add_argument("--config", metavar="JSON", help="options as one JSON object (keys as in the `sfm:` config section)")
    p.add_argument(
        "--mode",
        choices=MODES,
        help=f"auto: given when the scene's latent poses are ground truth (and allowed), else colmap; model: the poses "
        f"of an existing COLMAP model (--model DIR); resample: another B's SfM of the scene (--from DIR) read at "
        f"this B's latent times (default {_D.mode})",
    )
    p.add_argument("--model", dest="path", metavar="DIR", help="mode model: the COLMAP sparse model (binary or text)")
    p.add_argument("--from", dest="base", metavar="DIR",
                   help="mode resample: the scene's sfm/ output at another B, read at this EDI's latent "
                   "times")  # fmt: skip
    p.add_argument("--intrinsics-tolerance", type=float, metavar="T",
                   help="mode model: relative tolerance on the model's intrinsics "
                   f"(default {_D.intrinsics_tolerance})")  # fmt: skip
    p.add_argument("--no-given", dest="allow_given", action="store_const", const=False,
                   help="auto mode never picks given poses")  # fmt: skip
    p.add_argument("--matcher", choices=MATCHERS, help="auto: exhaustive up to 150 images, else sequential + "
                   f"spatial, then exhaustive if the scene stays split (default {_C.matcher})")  # fmt: skip
    p.add_argument("--global-mapping", action="store_const", const=True,
                   help="global (GLOMAP) instead of incremental mapping")  # fmt: skip
    p.add_argument("--refine-intrinsics", action="store_const", const=True,
                   help="let bundle adjustment refine the focal length")  # fmt: skip
    p.add_argument(
        "--min-registered-fraction",
        type=float,
        metavar="F",
        help=f"stop when fewer than this fraction of latent frames register (default {_D.min_registered_fraction})",
    )
    p.add_argument("--no-interpolate", dest="interpolate_unregistered", action="store_const", const=False,
                   help="leave unregistered latents NaN instead of interpolating")  # fmt: skip
    p.add_argument("--no-register-test", dest="register_test_cameras", action="store_const", const=False,
                   help="test cameras from the Sim(3) only")  # fmt: skip
    p.add_argument("--no-self-check", dest="self_check", action="store_const", const=False,
                   help="report the self-check of the camera path, but drop no view and never stop on it")  # fmt: skip
    p.add_argument("--feature-scale", type=int, metavar="F", help="SIFT upsampling (default auto)")
    p.add_argument("--max-features", dest="max_num_features", type=int, metavar="N",
                   help=f"SIFT features per image (default {_C.max_num_features})")  # fmt: skip
    p.add_argument("--device", choices=DEVICES, help=f"pycolmap device (default {_C.device})")
    p.add_argument("--seed", type=int, help=f"random seed of COLMAP's RANSAC and mapper (default {_C.seed})")
    p.add_argument("--keep-work", action="store_true", help="keep the database and scratch files in OUT/work")
    p.add_argument("--no-plot", action="store_true", help="skip report.png")


def options(args: argparse.Namespace) -> SfmConfig:
    """:class:`SfmConfig` from the defaults, ``--config`` and the flags given (in that order), checked; then the run
    control (``--keep-work``, ``-v``, ``--no-plot``, ``--threads``)."""
    import os
    from dataclasses import replace

    from eigs.util.options import accepted, flags, from_command_line

    cfg = from_command_line(SfmConfig, args.config, flags(args, accepted(SfmConfig)))
    threads = args.threads or min(2, os.cpu_count() or 1)
    return replace(cfg, base=args.base, keep_work=args.keep_work, verbose=args.verbose, plot=not args.no_plot,
                   colmap=replace(cfg.colmap, num_threads=threads))  # fmt: skip


def run(args: argparse.Namespace) -> int:
    from eigs.sfm.run import run_sfm

    run_sfm(args.scene, args.edi, args.output, latent_dir=args.latent_dir, cfg=options(args))
    return 0
