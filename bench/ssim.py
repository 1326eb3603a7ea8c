"""The training's SSIM: the fused kernel (eigs.metrics.fused_ssim) against the tensor-op reference (issue 46).

Writes the "fused-ssim" section of docs/benchmarks.md: forward plus backward of ``1 - SSIM`` (the D-SSIM of the
photometric loss, gradient to the render only) on stacks the training passes, ``K`` renders of ``H × W × 3`` in
[0, 1] against a noisy copy, at 1 and 2 threads; the median of ``--repeats`` calls after two warm-up calls, both
implementations interleaved in one process, and the largest difference of their values and gradients.

Run (a quiet machine): ``.venv/bin/python bench/ssim.py [--repeats 15] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from eigs.metrics.fused_ssim import ssim_fused  # noqa: E402
from eigs.metrics.pixel import ssim_torch  # noqa: E402

# (K renders, H, W): the single-render methods and the blur term; eigs+'s latent term (B = 4) at both sizes
CASES = [(1, 260, 346), (4, 260, 346), (1, 96, 128), (4, 96, 128)]


def step(fn, x: torch.Tensor, y: torch.Tensor) -> tuple[float, torch.Tensor, torch.Tensor]:
    """Seconds of one forward + backward of D-SSIM, its value and the gradient."""
    xg = x.clone().requires_grad_()
    t = time.perf_counter()
    loss = 1.0 - fn(xg, y)
    loss.backward()
    return time.perf_counter() - t, loss.detach(), xg.grad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=15)
    add_out_argument(ap)
    args = ap.parse_args()
    rows = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        for k, h, w in CASES:
            g = torch.Generator().manual_seed(0)
            x = torch.rand((k, 3, h, w), generator=g)
            y = (x + 0.05 * torch.randn((k, 3, h, w), generator=g)).clamp(0, 1)
            times: dict[str, list[float]] = {"ref": [], "fused": []}
            for i in range(args.repeats + 2):
                for name, fn in (("ref", ssim_torch), ("fused", ssim_fused)):
                    s, _, _ = step(fn, x, y)
                    if i >= 2:
                        times[name].append(s)
            _, v_ref, g_ref = step(ssim_torch, x.double(), y.double())
            _, v_fused, g_fused = step(ssim_fused, x, y)
            ref, fused = (statistics.median(times[n]) * 1e3 for n in ("ref", "fused"))
            rel = ((g_fused.double() - g_ref).abs().max() / g_ref.abs().max()).item()
            rows.append([f"{k} × {w}×{h}×3", str(threads), f"{ref:.1f}", f"{fused:.1f}", f"{ref / fused:.1f}×",
                         f"{abs(v_fused.item() - v_ref.item()):.1e}", f"{rel:.1e}"])  # fmt: skip
            print(rows[-1], flush=True)
    cols = ["renders", "threads", "reference ms", "fused ms", "speed-up", "|Δ D-SSIM| vs float64",
            "max rel. Δ gradient vs float64"]  # fmt: skip
    body = (
        "Forward + backward of the photometric loss's D-SSIM (`1 - SSIM`, 11-tap Gaussian, σ 1.5, zero padding; the "
        "gradient to the render only), float32, the tensor-op reference `ssim_torch` against the fused kernel "
        f"`ssim_fused`, interleaved in one process, median of {args.repeats} calls; the last two columns compare "
        "the fused kernel with the reference in float64 (`bench/ssim.py`).\n\n" + table(cols, rows) + "\n"
    )
    write_section("fused-ssim", "The fused SSIM (issue 46)", body, out=args.out)
    print(body)


if __name__ == "__main__":
    main()
