"""How a training step's cost grows with image size, Gaussian count and threads (issue 32, part 4).

``steps``: wall seconds per training step of some configured runs on one scene's artifacts, its images (blurry,
latent, ground truth) and event counts resized to each ``--sizes`` W×H (intrinsics scaled with them; bilinear for
images, nearest for counts and masks), its init cloud resampled to each ``--gaussians`` count
(bench/train.py ``resized_cloud``), at each ``--threads`` count; no densification, no held-out evaluation; median
of ``--repeats`` steps after two warm-up steps. One JSON record per point, appended to ``-o`` as it is measured
(a run cut short keeps what it measured).

Run: ``.venv/bin/python bench/cost.py steps --results results/d346-chair --config config/davis346.yaml
--runs 3dgs,edi-3dgs,eigs+ --sizes 128x96,346x260 --gaussians 20000 --threads 1,2 -o cost.jsonl``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.device_batch import merged_config  # noqa: E402
from bench.gpu_check import cpu_name  # noqa: E402
from bench.train import resized_cloud  # noqa: E402
from eigs.train.config import TrainConfig  # noqa: E402
from eigs.train.data import TrainData, load_train_data  # noqa: E402
from eigs.train.loop import Trainer  # noqa: E402
from eigs.util.memory import keep_freed_memory  # noqa: E402


def parse_size(text: str) -> tuple[int, int]:
    """``WxH`` → (W, H), both positive."""
    try:
        w, h = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise SystemExit(f"cost.py: --sizes: {text!r} is not WxH") from None
    if w < 8 or h < 8:
        raise SystemExit(f"cost.py: --sizes: {text!r} is smaller than 8x8")
    return w, h


def _images(x: torch.Tensor, h: int, w: int) -> torch.Tensor:
    """(..., H, W, C) float images → (..., h, w, C), bilinear."""
    lead = x.shape[:-3]
    y = x.reshape(-1, *x.shape[-3:]).permute(0, 3, 1, 2)
    y = F.interpolate(y, size=(h, w), mode="bilinear", align_corners=False)
    return y.permute(0, 2, 3, 1).reshape(*lead, h, w, x.shape[-1]).contiguous()


def _nearest(a, h: int, w: int):  # noqa: ANN001, ANN202
    """(..., H, W) numpy array of counts or a mask → (..., h, w), nearest pixel."""
    import numpy as np

    rows = np.minimum((np.arange(h) + 0.5) * a.shape[-2] / h, a.shape[-2] - 1).astype(int)
    cols = np.minimum((np.arange(w) + 0.5) * a.shape[-1] / w, a.shape[-1] - 1).astype(int)
    return np.ascontiguousarray(a[..., rows[:, None], cols[None, :]])


def resized(data: TrainData, w: int, h: int) -> TrainData:
    """``data`` seen by a camera of W×H pixels: images, event counts and intrinsics scaled, no held-out views."""
    K = data.K.clone()
    K[0] *= w / data.width
    K[1] *= h / data.height
    latent = _images(data.latent, h, w)
    edi = data.edi
    edi = dataclasses.replace(
        edi, latent=latent.numpy(), cum_counts=_nearest(edi.cum_counts, h, w),
        event_mask=None if edi.event_mask is None else _nearest(edi.event_mask, h, w),
        threshold_pos_map=None if edi.threshold_pos_map is None else _nearest(edi.threshold_pos_map, h, w),
        threshold_neg_map=None if edi.threshold_neg_map is None else _nearest(edi.threshold_neg_map, h, w),
    )  # fmt: skip
    sharp = None if data.sharp_train is None else _images(data.sharp_train, h, w)
    return dataclasses.replace(data, K=K, width=w, height=h, blurry=_images(data.blurry, h, w), latent=latent,
                               edi=edi, sharp_train=sharp, held_out=None)  # fmt: skip


def step_seconds(data: TrainData, run: dict, repeats: int) -> float:
    """Median wall seconds of one training step of ``run`` (a config's runs: entry) on ``data``."""
    options = {**run.get("options", {}), "method": run["method"], "densify": False}
    for key in ("steps", "schedule_steps", "eval_every"):
        options.pop(key, None)
    tr = Trainer(data, TrainConfig.from_dict(options), torch.device("cpu"))
    tr.warm_up()
    times = []
    for i in range(repeats + 2):
        t = time.perf_counter()
        tr.train_step()
        if i >= 2:
            times.append(time.perf_counter() - t)
    return statistics.median(times)


def steps(args: argparse.Namespace) -> None:
    keep_freed_memory()  # as `eigs train` does
    config = merged_config(args.config)
    runs = [r.strip() for r in args.runs.split(",") if r.strip()]
    for r in runs:
        if r not in config.get("runs", {}):
            raise SystemExit(f"cost.py: --runs: {r!r} is not a run of {', '.join(map(str, args.config))}")
    res = Path(args.results)
    b = res / f"b{args.bins}"
    base = load_train_data(res / "scene.h5", Path(args.edi) if args.edi else b / "edi.h5", b / "sfm", b / "init.ply")
    cloud = base.init
    machine = f"{cpu_name() or platform.processor() or 'unknown'}, {os.cpu_count()} cores, torch {torch.__version__}"
    out = Path(args.out)
    for size in args.sizes.split(","):
        w, h = parse_size(size)
        data = resized(base, w, h)
        for n in (int(x) for x in args.gaussians.split(",")):
            data.init = resized_cloud(cloud, n)
            for threads in (int(x) for x in args.threads.split(",")):
                torch.set_num_threads(threads)
                for r in runs:
                    s = step_seconds(data, config["runs"][r], args.repeats)
                    rec = {"scene": res.name, "run": r, "method": config["runs"][r]["method"], "width": w,
                           "height": h, "views": base.n_views, "gaussians": n, "threads": threads, "step_s": s,
                           "repeats": args.repeats, "machine": machine}  # fmt: skip
                    with out.open("a") as f:
                        f.write(json.dumps(rec) + "\n")
                    print(f"{r:10s} {w}x{h} {n:>7,} G {threads:>2} thr: {s * 1e3:8.1f} ms/step", flush=True)
        del data


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("steps", help="time training steps over sizes, Gaussian counts and threads")
    s.add_argument("--results", required=True, help="a scene's results folder (scene.h5, b<B>/edi.h5, sfm, init.ply)")
    s.add_argument("--bins", type=int, default=4)
    s.add_argument("--edi", help="the EDI file, when it is not <results>/b<B>/edi.h5")
    s.add_argument("--config", type=Path, nargs="+", required=True, help="config files with the runs")
    s.add_argument("--runs", required=True, help="comma-separated run names of the config")
    s.add_argument("--sizes", required=True, help="comma-separated WxH")
    s.add_argument("--gaussians", default="20000", help="comma-separated Gaussian counts")
    s.add_argument("--threads", default="1", help="comma-separated thread counts")
    s.add_argument("--repeats", type=int, default=5)
    s.add_argument("-o", "--out", required=True, help="JSON-lines file the records are appended to")
    a = ap.parse_args(argv)
    steps(a)


if __name__ == "__main__":
    main()
