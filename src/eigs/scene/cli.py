"""``eigs scene {info,validate} SCENE.h5``: inspect or check a scene file."""

from __future__ import annotations

import argparse

HELP = "inspect (info) or check (validate) a scene file"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "action", choices=("info", "validate"), help="info: print a summary; validate: check only"
    )
    parser.add_argument("scene", help="scene file (.h5)")


def run(args: argparse.Namespace) -> int:
    from eigs.scene import read_scene, summarize

    scene = read_scene(args.scene)
    if args.action == "info":
        print(summarize(scene))
    else:
        print(f"{args.scene}: valid eigs scene")
    return 0
