"""The field's trilinear interpolation: the kernel (eigs.render.trilinear) against grid_sample (issue 46).

Writes the "trilinear" section of docs/benchmarks.md: forward plus backward of the interpolation of a voxel grid at
``N`` points (the field methods' training step at 128×96: a 4-channel 67×26×68 grid, ~212,000 samples a step), the
gradient to the grid alone (`nerf`, `edi-nerf`, `e2nerf`) and to the grid and the points (`deblur-nerf`, whose rays
move), at 1 and 2 threads; median of ``--repeats`` calls, both interleaved in one process, and the largest
difference from grid_sample in float64.

Run (a quiet machine): ``.venv/bin/python bench/trilinear.py [--repeats 9] [--out DIR]``.
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
from eigs.render.trilinear import trilinear, trilinear_reference  # noqa: E402

GRID, POINTS = (1, 4, 68, 26, 67), 212_000


def once(fn, grid: torch.Tensor, u: torch.Tensor, v: torch.Tensor, need_u: bool):
    """Seconds of forward + backward, the values and the gradients."""
    g = grid.clone().requires_grad_()
    p = u.clone().requires_grad_(need_u)
    t = time.perf_counter()
    out = fn(g, p)
    out.backward(v)
    return time.perf_counter() - t, out.detach(), g.grad, p.grad


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=9)
    add_out_argument(ap)
    args = ap.parse_args()
    gen = torch.Generator().manual_seed(0)
    grid = torch.randn(GRID, generator=gen)
    u = torch.rand((POINTS, 3), generator=gen)
    v = torch.randn((POINTS, GRID[1]), generator=gen)
    rows = []
    for threads in (1, 2):
        torch.set_num_threads(threads)
        for need_u in (False, True):
            times: dict[str, list[float]] = {"ref": [], "kernel": []}
            for i in range(args.repeats + 1):
                for name, fn in (("ref", trilinear_reference), ("kernel", trilinear)):
                    s = once(fn, grid, u, v, need_u)[0]
                    if i:
                        times[name].append(s)
            _, o64, g64, u64 = once(trilinear_reference, grid.double(), u.double(), v.double(), need_u)
            _, o32, g32, u32 = once(trilinear, grid, u, v, need_u)
            err = max((a.double() - b).abs().max().item() / max(b.abs().max().item(), 1.0)
                      for a, b in ((o32, o64), (g32, g64), *(((u32, u64),) if need_u else ())))  # fmt: skip
            ref, ker = (statistics.median(times[n]) * 1e3 for n in ("ref", "kernel"))
            rows.append([str(threads), "grid and points" if need_u else "grid", f"{ref:.1f}", f"{ker:.1f}",
                         f"{ref / ker:.1f}×", f"{err:.1e}"])  # fmt: skip
            print(rows[-1], flush=True)
    body = (
        f"Forward + backward of the trilinear interpolation of a {GRID[1]}-channel {GRID[4]}×{GRID[3]}×{GRID[2]} "
        f"grid at {POINTS:,} uniform random points, float32, grid_sample (border padding, aligned corners) against "
        f"the kernel, median of {args.repeats} calls interleaved in one process; `max rel. Δ`: the largest "
        "difference of the values and gradients from grid_sample in float64, over the largest magnitude "
        "(`bench/trilinear.py`).\n\n"
        + table(["threads", "gradient to", "grid_sample ms", "kernel ms", "speed-up", "max rel. Δ"], rows) + "\n"
    )
    write_section("trilinear", "The field's trilinear interpolation (issue 46)", body, out=args.out)
    print(body)


if __name__ == "__main__":
    main()
