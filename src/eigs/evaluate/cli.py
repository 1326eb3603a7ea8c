"""``eigs evaluate``: score a trained run (test-camera renders, or BRISQUE on training views and a render path)."""

from __future__ import annotations

import argparse

from eigs.evaluate.options import EvaluateOptions

HELP = "evaluate a trained run: PSNR/SSIM/LPIPS at the test cameras, or BRISQUE without ground truth; FPS, size"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = (
        "Writes OUTPUT (metrics.json), per_image.csv and renders/ (8-bit PNGs, the images that were scored) in "
        "OUTPUT's folder. docs/evaluation.md describes the protocol and the fields."
    )
    p.add_argument("run", help="run folder (model.ply or model.npz, config.json)")
    p.add_argument("scene", help="scene file (scene.h5): ground truth, background")
    p.add_argument("sfm", help="SfM output directory (poses.h5, test_cameras.h5)")
    p.add_argument("-o", "--output", required=True, help="metrics.json to write")
    p.add_argument("--path-frames", type=int, default=None, help="render-path frames (ellipse or orbit) scored on "
                   f"scenes without ground truth (default {EvaluateOptions.path_frames})")  # fmt: skip
    p.add_argument("--test-pose-iters", type=int, default=None, help="also score the second protocol: every test "
                   "camera refined against its image on the frozen model for this many iterations (default "
                   f"{EvaluateOptions.test_pose_iters}: off)")  # fmt: skip
    p.add_argument("--hidden-ground-truth", action="store_true", help="the scene is a recording through the "
                   "real-data path whose ground truth was kept aside for scoring (ingested with --groundtruth): "
                   "score BRISQUE (training views, path) as well as the test cameras")  # fmt: skip
    p.add_argument("--resources", default=None, metavar="DIR", help="model files made by `eigs resources`")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))


def run(args: argparse.Namespace) -> int:
    import logging

    from eigs.evaluate.core import evaluate_run
    from eigs.util.options import accepted, flags, from_command_line

    opts = from_command_line(EvaluateOptions, None, flags(args, accepted(EvaluateOptions)), "eigs evaluate")
    res = evaluate_run(args.run, args.scene, args.sfm, args.output, resources=args.resources,
                       path_frames=opts.path_frames, device=args.device, test_pose_iters=opts.test_pose_iters,
                       hidden_ground_truth=args.hidden_ground_truth)  # fmt: skip
    m = res["metrics"]
    summary = ", ".join(
        f"{k}: " + " ".join(f"{n}={v:.4g}" for n, v in g.items() if isinstance(v, float)) for k, g in m.items()
    )
    size = f"{res['n_gaussians']} Gaussians" if res["n_gaussians"] is not None else f"{res['n_voxels']} voxels"
    logging.getLogger("eigs.evaluate").info("wrote %s (%s; %.1f FPS, %s)", args.output, summary,
                                            res["fps"] or float("nan"), size)  # fmt: skip
    return 0
