"""``eigs train``: train one method on a scene's artifacts into a run folder."""

from __future__ import annotations

import argparse

HELP = "train a method (Gaussian: 3dgs, eigs, …; radiance field: nerf, e2nerf, …) into a run folder"


def add_arguments(p: argparse.ArgumentParser) -> None:
    # optional for argparse so that `eigs train --list` needs nothing else; run() checks them otherwise
    p.add_argument("scene", nargs="?", help="scene file (scene.h5)")
    p.add_argument("edi", nargs="?", help="EDI artifact (b{B}/edi.h5)")
    p.add_argument("sfm", nargs="?", help="SfM output directory (b{B}/sfm/ with poses.h5, test_cameras.h5)")
    p.add_argument("init", nargs="?", help="initial Gaussians (b{B}/init.ply)")
    p.add_argument("-o", "--output", help="run folder to write (model.ply or model.npz, config.json, train_log.csv)")
    p.add_argument("--method", default=None, help="method name (default: the config's, else 3dgs); see --list")
    p.add_argument(
        "--config",
        default="{}",
        metavar="JSON",
        help="training options as a JSON object (keys of eigs.train.config.TrainConfig; the workflow passes the "
        "run's `options:` here); without `steps` a method trains for its default budget (eigs.train.catalog)",
    )
    p.add_argument("--steps", type=int, default=None, help="override the number of steps")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"), help="auto: CUDA when available")
    p.add_argument(
        "--list",
        action="store_true",
        help="list the methods and exit ([needs events]: not scheduled on scenes configured with `events: false`)",
    )


def run(args: argparse.Namespace) -> int:
    import logging

    import torch

    from eigs.errors import EigsError
    from eigs.train.catalog import FIELD, METHODS, trainer_class
    from eigs.train.data import load_train_data
    from eigs.train.loop import fit
    from eigs.train.resolve import resolve_run
    from eigs.util.options import parse_config_json

    if args.list:
        for name, spec in sorted(METHODS.items()):
            events = " [needs events]" if spec.needs_events else ""
            print(f"{name:16s} {spec.description}{events}")
        return 0
    missing = [n for n in ("scene", "edi", "sfm", "init", "output") if getattr(args, n) is None]
    if missing:
        usage = "eigs train SCENE.h5 EDI.h5 SFM_DIR INIT.ply -o RUN_DIR"
        raise EigsError("eigs train", f"missing {', '.join(missing)}: {usage}")
    cfg, options = resolve_run(parse_config_json(args.config), "--config", args.method, args.steps)
    if args.device == "cuda" and not torch.cuda.is_available():
        raise EigsError("--device", "cuda requested but no CUDA device is available")
    device = torch.device("cuda" if args.device == "cuda" or (args.device == "auto" and torch.cuda.is_available())
                          else "cpu")  # fmt: skip
    data = load_train_data(args.scene, args.edi, args.sfm, args.init)
    inputs = {"scene": args.scene, "edi": args.edi, "sfm": args.sfm, "init": args.init}
    trainer = trainer_class(cfg.method)  # its family's (eigs.train.catalog.FAMILIES)
    res = fit(trainer(data, cfg, device, options), args.output, inputs=inputs)
    final = res.rows[-1] if res.rows else {}
    size = f"{res.model.n_voxels} voxels" if METHODS[cfg.method].family == FIELD else f"{len(res.model)} Gaussians"
    logging.getLogger("eigs.train").info(
        "wrote %s: %s, %.1f s of training, held-out PSNR novel %s dB",
        args.output, size, res.train_seconds, final.get("psnr_novel", "n/a"),
    )  # fmt: skip
    return 0
