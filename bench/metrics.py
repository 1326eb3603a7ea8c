"""Time each image-quality metric per 512x512 pair on 2 threads; writes the "metrics" section of docs/benchmarks.md.

Run: ``.venv/bin/python bench/metrics.py [--quick] [--resources DIR] [--out DIR]`` (needs ``eigs resources`` for
LPIPS/BRISQUE; prepares them if absent). ``--quick``: a fifth of the repeats (at least one).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import torch
from matplotlib import cbook

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from eigs.metrics import resources  # noqa: E402
from eigs.metrics.image import read_image  # noqa: E402
from eigs.metrics.noreference import brisque  # noqa: E402
from eigs.metrics.perceptual import lpips  # noqa: E402
from eigs.metrics.pixel import psnr, ssim, ssim_torch  # noqa: E402

THREADS = 2


def timed(fn: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter) -> float:
    """Median time in ms of ``fn`` on ``clock`` after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        t = clock()
        fn()
        times.append((clock() - t) * 1e3)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a fifth of the repeats (at least one): a first look")
    ap.add_argument("--resources", help="model files made by `eigs resources` (default: eigs' resources folder)")
    add_out_argument(ap)
    args = ap.parse_args()
    if args.resources:
        os.environ["EIGS_RESOURCES"] = args.resources
    torch.set_num_threads(THREADS)
    cv2.setNumThreads(THREADS)
    resources.prepare()
    sharp = read_image(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[44:556, :512]
    blurred = cv2.GaussianBlur(sharp, (0, 0), 2)
    assert sharp.shape == (512, 512, 3)

    xt = torch.from_numpy(blurred.transpose(2, 0, 1) / 255.0).float()[None]
    yt = torch.from_numpy(sharp.transpose(2, 0, 1) / 255.0).float()[None]

    def dssim_step() -> None:
        x = xt.clone().requires_grad_(True)
        (1 - ssim_torch(x, yt)).backward()

    cases: list[tuple[str, str, Callable[[], object], int]] = [
        ("psnr", "NumPy float64, uint8 input", lambda: psnr(blurred, sharp), 20),
        ("ssim 3dgs", "torch float64 (evaluation API)", lambda: ssim(blurred, sharp, "3dgs"), 10),
        ("ssim 3dgs", "torch float32 forward (`ssim_torch`)", lambda: ssim_torch(xt, yt), 10),
        ("ssim 3dgs", "torch float32 forward + backward (D-SSIM loss)", dssim_step, 10),
        ("ssim skimage-gaussian", "torch float64", lambda: ssim(blurred, sharp, "skimage-gaussian"), 10),
        ("ssim deblurnerf", "torch float64", lambda: ssim(blurred, sharp, "deblurnerf"), 10),
        ("lpips alex", "float32, no_grad", lambda: lpips(blurred, sharp, "alex"), 10),
        ("lpips vgg", "float32, no_grad", lambda: lpips(blurred, sharp, "vgg"), 3),
        ("brisque", "one image (no reference)", lambda: brisque(blurred), 10),
    ]
    load_before = Path("/proc/loadavg").read_text().split()[0]
    rows = []
    for name, how, fn, repeats in cases:
        repeats = max(1, repeats // 5) if args.quick else repeats
        torch.set_num_threads(THREADS)
        cv2.setNumThreads(THREADS)
        wall = timed(fn, repeats)
        torch.set_num_threads(1)
        cv2.setNumThreads(1)
        cpu = timed(fn, repeats, time.process_time)
        rows.append([name, how, wall, cpu])
        print(f"{name:24s} {how:48s} {wall:9.2f} ms wall (2 thr) {cpu:9.2f} ms CPU (1 thr)", flush=True)
    load_after = Path("/proc/loadavg").read_text().split()[0]
    headers = ["metric", "how", f"wall ms, {THREADS} threads", "CPU ms, 1 thread"]
    body = (
        "Median time per 512x512 RGB pair (matplotlib's `grace_hopper.jpg` cropped, against its σ = 2 blur) after "
        f"one warm-up call: wall time with {THREADS} torch/OpenCV threads, and process CPU time with 1 thread "
        "(robust to other jobs on a shared machine; about the wall time on an idle core). 1-minute load average "
        f"{load_before} before and {load_after} after: a load above the core count inflates wall times, torch's "
        "multi-threaded element-wise ops most.\n\n" + table(headers, rows)
    )
    torch.set_num_threads(THREADS)  # the section's stamp reports torch's thread count
    data = [{"metric": n, "how": h, "wall_ms": w, "cpu_ms": c} for n, h, w, c in rows]
    write_section("metrics", "Image-quality metrics", body, data=data, out=args.out)


if __name__ == "__main__":
    main()
