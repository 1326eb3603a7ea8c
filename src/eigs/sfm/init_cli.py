"""``eigs init``: initial Gaussians (3DGS PLY) from the SfM points."""

from __future__ import annotations

import argparse

HELP = "initial Gaussians from the SfM points, written as a standard 3DGS PLY"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("sfm", help="SfM output directory (sfm/ with points3D.bin and poses.h5)")
    p.add_argument("-o", "--output", required=True, help="output PLY (init.ply)")
    p.add_argument(
        "--min-points",
        type=int,
        default=1000,
        metavar="N",
        help="with fewer SfM points, add random Gaussians in the scene bounds (default 1000)",
    )
    p.add_argument("--random", type=int, default=10_000, metavar="N", help="random Gaussians added (default 10000)")
    p.add_argument("--sh-degree", type=int, default=3, choices=range(0, 5), metavar="D", help="SH degree (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the random Gaussians")


def run(args: argparse.Namespace) -> int:
    import logging
    from pathlib import Path

    import numpy as np

    from eigs.artifacts.gaussians import write_gaussian_ply
    from eigs.artifacts.poses import read_poses
    from eigs.errors import EigsError
    from eigs.sfm.init import initialize

    log = logging.getLogger("eigs.sfm.init")
    sfm = Path(args.sfm)
    if not (sfm / "points3D.bin").is_file():
        raise EigsError(sfm, "no points3D.bin (not an sfm/ output directory; run `eigs sfm` first)")
    from eigs.sfm.colmap import load_pycolmap

    pycolmap = load_pycolmap()
    try:
        rec = pycolmap.Reconstruction(str(sfm))
    except Exception as err:  # pycolmap raises RuntimeError/ValueError for broken models
        raise EigsError(sfm, f"cannot read the COLMAP model ({err})") from None
    pts = list(rec.points3D.values())
    xyz = np.array([p.xyz for p in pts], np.float64).reshape(-1, 3)
    rgb = np.array([p.color for p in pts], np.float64).reshape(-1, 3) / 255.0
    poses = read_poses(sfm)
    centres = poses.c2w[..., :3, 3].reshape(-1, 3)
    res = initialize(
        xyz, rgb, centres, min_points=args.min_points, n_random=args.random, sh_degree=args.sh_degree, seed=args.seed
    )
    write_gaussian_ply(res.cloud, args.output)
    log.info("wrote %s: %d Gaussians (%d from SfM points, %d random)", args.output, len(res.cloud), res.n_sfm,
             res.n_random)  # fmt: skip
    return 0
