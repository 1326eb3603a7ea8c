"""Time each image-quality metric per 512x512 pair on 2 threads; writes the "metrics" section of docs/benchmarks.md.

Run: ``.venv/bin/python bench/metrics.py`` (needs ``eigs resources`` for LPIPS/BRISQUE; prepares them if absent).
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import torch
from matplotlib import cbook

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import table, write_section  # noqa: E402
from eigs.metrics import resources  # noqa: E402
from eigs.metrics.image import read_image  # noqa: E402
from eigs.metrics.noreference import brisque  # noqa: E402
from eigs.metrics.perceptual import lpips  # noqa: E402
from eigs.metrics.pixel import psnr, ssim, ssim_torch  # noqa: E402

THREADS = 2


def timed(fn: Callable[[], object], repeats: int) -> float:
    """Median wall time in ms of ``fn`` after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def main() -> None:
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
    rows = []
    for name, how, fn, repeats in cases:
        ms = timed(fn, repeats)
        rows.append([name, how, ms])
        print(f"{name:24s} {how:48s} {ms:9.2f} ms", flush=True)
    body = (
        f"Median wall time per 512x512 RGB pair (matplotlib's `grace_hopper.jpg` cropped, against its σ = 2 blur), "
        f"{THREADS} torch/OpenCV threads, after one warm-up call.\n\n" + table(["metric", "how", "ms per pair"], rows)
    )
    write_section("metrics", "Image-quality metrics", body)


if __name__ == "__main__":
    main()
