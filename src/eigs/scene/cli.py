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
    from eigs.scene import EventFile, has_raw_events, read_scene, summarize

    # the header whole, the raw events a chunk at a time (checked as they are read): a recording larger than
    # memory is inspected and validated in bounded memory
    scene = read_scene(args.scene, events=False)
    events = EventFile(args.scene) if has_raw_events(args.scene) else None
    if events is not None and args.action == "validate":
        for _ in events.chunks():
            pass
    if args.action == "info":
        print(summarize(scene, events=events))
    else:
        print(f"{args.scene}: valid eigs scene")
    return 0
