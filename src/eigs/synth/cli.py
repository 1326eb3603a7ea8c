"""``eigs synth``: generate a built-in synthetic scene (blurry frames, events, ground truth)."""

from __future__ import annotations

import argparse

HELP = "generate a built-in synthetic scene (ray-cast, shaken camera, simulated events, ground truth)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scene", metavar="NAME", help="built-in scene name (see --list)")
    parser.add_argument("--list", action="store_true", help="list the built-in scenes and their parameters, exit")
    parser.add_argument(
        "--config",
        metavar="JSON|FILE.yaml",
        help="scene parameters as one JSON object (what the rule passes: the scene's `overrides:`) or a YAML file",
    )
    parser.add_argument(
        "--overrides",
        metavar="JSON",
        default="{}",
        help='JSON object of scene parameters, applied after --config, e.g. \'{"seed": 3, "shake": 0}\'',
    )
    parser.add_argument(
        "--preset",
        metavar="NAME",
        help="a named camera/capture preset applied over the scene's defaults and under --config/--overrides "
        "(e.g. davis346; eigs synth --list shows them)",
    )
    parser.add_argument("-o", "--output", metavar="scene.h5", help="scene file to write")
    parser.add_argument("--contact-sheet", metavar="sheet.png", help="also write a contact sheet PNG")
    parser.add_argument(
        "--e2nerf-layout",
        metavar="DIR",
        help="also write the E²NeRF synthetic layout (transform_train.json, train/, test/, events.pt) to DIR",
    )
    parser.add_argument(
        "--e2nerf-real-layout",
        metavar="DIR",
        help="also write the E²NeRF real (LLFF) layout (images/, events.pt, poses_bounds.npy; no ground truth) to "
        "DIR, and its ground truth to --groundtruth-out",
    )
    parser.add_argument(
        "--groundtruth-out",
        metavar="FILE.h5",
        help="with --e2nerf-real-layout: the ground-truth scene file, outside DIR (default DIR.groundtruth.h5)",
    )
    parser.add_argument(
        "--image-format",
        choices=("jpg", "png"),
        default="jpg",
        help="with --e2nerf-real-layout: jpg (quality 95, as E²NeRF) or png (lossless); default jpg",
    )


def _list() -> str:
    from eigs.synth.scenes import DEFAULTS, SCENES

    lines = ["built-in scenes:"]
    for name, spec in SCENES.items():
        own = ", ".join(f"{k}={v}" for k, v in spec.params.items())
        lines.append(f"  {name:8s} {spec.description}" + (f"  [{own}]" if own else ""))
    lines.append("parameters (defaults; override with --config/--overrides):")
    lines += [f"  {k} = {v!r}" for k, v in DEFAULTS.items()]
    from eigs.synth.scenes import PRESET_SOURCES, PRESETS

    lines.append("presets (--preset NAME or \"preset\": NAME; sources in docs/synthetic.md):")
    for name, values in PRESETS.items():
        lines.append(f"  {name}:")
        lines += [f"    {k} = {v!r}    # {PRESET_SOURCES[name][k]}" for k, v in values.items()]
    from dataclasses import asdict

    from eigs.synth.frame_noise import MODELS, SOURCES

    lines.append("frame noise models (\"frame_noise\": NAME; default none; docs/synthetic.md, 'Frame noise'):")
    for name, model in MODELS.items():
        lines.append(f"  {name}:")
        lines += [f"    {k} = {v:.6g}    # {SOURCES[name][k]}" for k, v in asdict(model).items()]
    lines.append("blur synthesis (\"blur_synthesis\": NAME; default average; docs/synthetic.md, 'Blur synthesis'):")
    lines.append("  average: the mean of all subframes + 1 sub-frames of the exposure (linear)")
    lines.append("  e2nerf:  E²NeRF's: the mean of 17 renders at k·T/16, k = 0..16 (linear, clamped), then the "
                 "scene's camera_response; needs subframes a multiple of 16 (eigs.synth.blur)")
    return "\n".join(lines)


def _load_overrides(args: argparse.Namespace) -> list[tuple[str, dict | None]]:
    import json
    from pathlib import Path

    from eigs.errors import EigsError

    layers: list[tuple[str, dict | None]] = []
    if args.config and args.config.lstrip().startswith("{"):
        from eigs.util.options import parse_config_json

        layers.append(("--config", parse_config_json(args.config)))
    elif args.config:
        import yaml

        p = Path(args.config)
        if not p.is_file():
            raise EigsError(p, "no such config file")
        try:
            data = yaml.safe_load(p.read_text()) or {}
        except yaml.YAMLError as err:
            raise EigsError(p, f"not valid YAML ({err})") from None
        if not isinstance(data, dict):
            raise EigsError(p, "must be a YAML mapping of scene parameters")
        layers.append((str(p), data))
    try:
        ov = json.loads(args.overrides or "{}")
    except json.JSONDecodeError as err:
        raise EigsError("--overrides", f"not valid JSON ({err})") from None
    if not isinstance(ov, dict):
        raise EigsError("--overrides", "must be a JSON object of parameter → value")
    if getattr(args, "preset", None):
        layers.insert(0, ("--preset", {"preset": args.preset}))
    layers.append(("--overrides", ov))
    return layers


def run(args: argparse.Namespace) -> int:
    from eigs.errors import EigsError

    if args.list:
        print(_list())
        return 0
    if not args.scene:
        raise EigsError("--scene", "give a built-in scene name (eigs synth --list shows them)")
    if not (args.output or args.e2nerf_layout or args.contact_sheet or args.e2nerf_real_layout):
        raise EigsError("-o", "nothing to write: give -o scene.h5 (and/or --contact-sheet, --e2nerf-layout, "
                        "--e2nerf-real-layout)")
    if args.groundtruth_out and not args.e2nerf_real_layout:
        raise EigsError("--groundtruth-out", "only with --e2nerf-real-layout")
    from eigs.synth.scenes import get_spec

    get_spec(args.scene)  # fail fast on a bad name
    layers = _load_overrides(args)

    from eigs.synth.generate import generate, scene_camera

    threads = max(1, args.threads or 1)
    view_events = None
    if args.output and not (args.e2nerf_layout or args.e2nerf_real_layout):
        # the events go to the scene file as they are simulated: memory holds one view's, not the recording's
        from eigs.scene import SceneWriter, read_events

        with SceneWriter(args.output, None, camera=scene_camera(args.scene, layers=layers)) as w:
            g = generate(args.scene, layers=layers, threads=threads,
                         event_sink=lambda c: w.append_events(c.x, c.y, c.t, c.p))
            w.set_header(g.scene)
            w.set_view_index(g.view_index)
        view_events = lambda v: read_events(args.output, *(int(k) for k in g.view_index[v]))  # noqa: E731
    else:  # the layouts' writers take the events from memory
        g = generate(args.scene, layers=layers, threads=threads)
        if args.output:
            from eigs.scene import write_scene

            write_scene(g.scene, args.output)
    if args.contact_sheet:
        from eigs.synth.contact_sheet import write_contact_sheet

        write_contact_sheet(g.scene, args.contact_sheet, view_events=view_events)
    if args.e2nerf_layout:
        from eigs.synth.export_e2nerf import write_e2nerf_synthetic

        write_e2nerf_synthetic(g, args.e2nerf_layout)
    if args.e2nerf_real_layout:
        from eigs.synth.export_e2nerf_real import write_e2nerf_real

        write_e2nerf_real(g, args.e2nerf_real_layout, groundtruth=args.groundtruth_out,
                          image_format=args.image_format)
    return 0
