"""``eigs render``: render a trained run's model (``model.ply``, or ``model.npz`` of a field run) at the test
cameras, the training views' reference poses or an orbit, write 8-bit PNGs and report frames per second."""

from __future__ import annotations

import argparse

HELP = "render a trained run (test cameras, training views or an orbit) to PNGs and report FPS"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run folder (model.ply or model.npz, config.json)")
    p.add_argument("scene", help="scene file (scene.h5): camera, background")
    p.add_argument("sfm", help="SfM output directory (poses.h5, test_cameras.h5)")
    p.add_argument("--cameras", default="test", choices=("test", "train", "orbit"), help="which cameras")
    p.add_argument("--frames", type=int, default=60, help="orbit frames (default 60)")
    p.add_argument("-o", "--output", required=True, help="output directory of PNGs and render_report.json")
    p.add_argument("--device", default="auto", choices=("auto", "cpu", "cuda"))


def run(args: argparse.Namespace) -> int:
    import json
    import logging
    import time
    from pathlib import Path

    import numpy as np
    import torch

    from eigs.artifacts import run as run_folder
    from eigs.artifacts.field import FIELD_FILE, read_field
    from eigs.artifacts.gaussians import read_gaussian_ply
    from eigs.artifacts.poses import read_poses, read_test_cameras
    from eigs.errors import EigsError
    from eigs.evaluate.renderer import cloud_tensors
    from eigs.render.field import FieldTensors, render_image
    from eigs.render.gaussians import render_gaussians
    from eigs.scene import read_scene
    from eigs.util.atomic import atomic_path
    from eigs.util.cameras import orbit_cameras
    from eigs.util.image import write_png

    log = logging.getLogger("eigs.render")
    run_dir = Path(args.run)
    cfg_path = run_dir / run_folder.CONFIG
    try:
        sh_degree = int(run_folder.read_config(run_dir)["train"]["sh_degree"])
    except (ValueError, KeyError, TypeError) as err:
        raise EigsError(cfg_path, f"unreadable run config ({err})") from None
    scene = read_scene(args.scene, events=False)
    device = torch.device("cuda" if args.device == "cuda" or (args.device == "auto" and torch.cuda.is_available())
                          else "cpu")  # fmt: skip
    field: FieldTensors | None = None
    if (run_dir / FIELD_FILE).is_file():
        field = FieldTensors.from_arrays(read_field(run_dir / FIELD_FILE), device)
        size = {"n_voxels": field.n_voxels}
    else:
        model = cloud_tensors(read_gaussian_ply(run_dir / run_folder.MODEL_PLY), sh_degree, scene.channels, device)
        size = {"n_gaussians": len(model)}
    c = scene.channels
    bg = torch.tensor(np.asarray(scene.background if scene.background is not None else np.zeros(c), np.float32))
    poses = read_poses(args.sfm)
    w, h = poses.width, poses.height
    if args.cameras == "test":
        tc = read_test_cameras(args.sfm)
        c2w, ks = tc.c2w, tc.K
        names = [f"test_{i:04d}.png" for i in range(len(tc))]
    else:
        valid = poses.valid[:, 0]
        if args.cameras == "train":
            c2w = poses.c2w[valid, 0]
            names = [f"train_{v:04d}.png" for v in np.nonzero(valid)[0]]
        else:
            c2w = orbit_cameras(poses.c2w[valid, 0], args.frames)
            names = [f"orbit_{i:04d}.png" for i in range(args.frames)]
        ks = np.repeat(poses.K[None], len(c2w), axis=0)
    if len(c2w) == 0:
        raise EigsError(args.sfm, f"no {args.cameras} cameras to render")
    times = []
    with torch.no_grad(), atomic_path(args.output, directory=True) as tmp:
        for i in range(len(c2w)):
            t0 = time.perf_counter()
            k = torch.from_numpy(ks[i]).float().to(device)
            if field is not None:
                img = render_image(field, torch.from_numpy(c2w[i]), k, w, h, bg.to(device))
            else:
                img, _, _ = render_gaussians(
                    model.means, model.quats, model.log_scales, model.opacity_logits, model.sh,
                    torch.from_numpy(c2w[i]), k, w, h, background=bg.to(device), sh_degree=model.sh_degree,
                )  # fmt: skip
            times.append(time.perf_counter() - t0)
            write_png(tmp / names[i], img.clamp(0, 1).cpu().numpy())
        fps = len(times) / max(sum(times), 1e-12)
        report = {"cameras": args.cameras, "frames": len(times), "fps": fps, "mean_ms": 1e3 * float(np.mean(times)),
                  **size, "width": w, "height": h, "device": str(device)}  # fmt: skip
        (tmp / "render_report.json").write_text(json.dumps(report, indent=2) + "\n")
    log.info("rendered %d %s frames to %s: %.1f FPS (%.2f ms per frame, %s)", len(times), args.cameras,
             args.output, fps, report["mean_ms"], size)  # fmt: skip
    return 0
