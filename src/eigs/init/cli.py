"""``eigs init``: initial Gaussians (3DGS PLY) from the SfM points.

Options: every default lives in :class:`eigs.init.options.InitOptions`; ``--config JSON`` (the rule's ``init:``
config section) sets any of them, and a flag given here wins over it.
"""

from __future__ import annotations

import argparse

from eigs.init.options import InitOptions

HELP = "initial Gaussians from the SfM points, written as a standard 3DGS PLY"
_D = InitOptions()


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sfm", help="SfM output directory (sfm/ with points3D.bin and poses.h5)")
    p.add_argument("-o", "--output", required=True, help="output PLY (init.ply)")
    p.add_argument(
        "--config", metavar="JSON", help="options as one JSON object (keys as in the `init:` config section)"
    )
    p.add_argument(
        "--min-points",
        type=int,
        metavar="N",
        help=f"with fewer SfM points, add random Gaussians in the scene bounds (default {_D.min_points})",
    )
    p.add_argument("--random", type=int, metavar="N", help=f"random Gaussians added (default {_D.random})")
    p.add_argument(
        "--sh-degree", type=int, choices=range(0, 5), metavar="D", help=f"SH degree (default {_D.sh_degree})"
    )
    p.add_argument("--seed", type=int, help=f"seed of the random Gaussians (default {_D.seed})")


def options(args: argparse.Namespace) -> InitOptions:
    """:class:`InitOptions` from the defaults, ``--config`` and the flags given (in that order), checked."""
    from eigs.util.options import accepted, flags, from_command_line

    return from_command_line(InitOptions, args.config, flags(args, accepted(InitOptions)))


def run(args: argparse.Namespace) -> int:
    import logging
    from pathlib import Path

    from eigs.artifacts.colmap import read_points
    from eigs.artifacts.gaussians import write_gaussian_ply
    from eigs.artifacts.poses import read_poses
    from eigs.init.initialize import initialize

    log = logging.getLogger("eigs.init")
    opts = options(args)
    sfm = Path(args.sfm)
    xyz, rgb = read_points(sfm)
    poses = read_poses(sfm)
    centres = poses.c2w[..., :3, 3].reshape(-1, 3)
    res = initialize(
        xyz, rgb, centres, min_points=opts.min_points, n_random=opts.random, sh_degree=opts.sh_degree, seed=opts.seed
    )
    write_gaussian_ply(res.cloud, args.output)
    log.info("wrote %s: %d Gaussians (%d from SfM points, %d random)", args.output, len(res.cloud), res.n_sfm,
             res.n_random)  # fmt: skip
    return 0
