"""How much of each scene's texture the blur term's SSIM can see (issue 43, part 4; docs/results.md "Why `eigs+`
renders smooth at 346×260").

Per scene, over its blurry training frames (luma, 8-bit DN): the mean, and the median over pixels of the local
variance in SSIM's window (11 × 11 Gaussian, σ = 1.5 px: E_w[x²] − E_w[x]², "valid" positions only), against SSIM's
constant C2 = (0.03 · 255)² = 58.5 DN² at data range 1. Where the local variance is far below C2, SSIM's contrast
term is flat in the texture and the blur term's D-SSIM barely asks for it.

Run: ``.venv/bin/python bench/frame_light.py results/chair results/d346-chair … [--out DIR]`` (each argument a
scene's results folder holding ``scene.h5``); the section is ``frame-light`` in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, fixed, table, write_section  # noqa: E402
from eigs.metrics.pixel import gaussian_window  # noqa: E402
from eigs.scene.file import read_scene  # noqa: E402

C2_DN2 = (0.03 * 255.0) ** 2  # SSIM's C2 at data range 1, in DN² (58.5)
LUMA = (0.299, 0.587, 0.114)  # Rec. 601 weights of R, G, B


def luma_dn(frames: np.ndarray) -> np.ndarray:
    """(N, H, W, C) uint8 or float in DN → (N, H, W) float64 luma in DN (a single channel passes through)."""
    x = np.asarray(frames, dtype=np.float64)
    if x.ndim == 3:
        return x
    if x.shape[-1] == 1:
        return x[..., 0]
    return x[..., :3] @ np.asarray(LUMA)


def local_variance(images: np.ndarray) -> np.ndarray:
    """(N, H, W) float64 → (N, H − 10, W − 10) local variance in SSIM's window, float64 (≥ 0: rounding below 0 is
    clipped; exact to ~1e-12 relative to the squared values)."""
    if images.ndim != 3 or images.shape[1] < 11 or images.shape[2] < 11:
        raise ValueError(f"images must be (N, H ≥ 11, W ≥ 11), got {images.shape}")
    g = gaussian_window(11, 1.5, dtype=torch.float64)
    w = torch.outer(g, g)[None, None]  # (1, 1, 11, 11), sums to 1
    x = torch.from_numpy(np.ascontiguousarray(images))[:, None]
    mean = torch.nn.functional.conv2d(x, w)
    mean_sq = torch.nn.functional.conv2d(x * x, w)
    return (mean_sq - mean * mean).clamp_min(0.0)[:, 0].numpy()


def scene_light(scene_h5: Path) -> dict[str, float]:
    """A scene's blurry frames: mean DN, median local variance (DN²) and its ratio to C2."""
    scene = read_scene(scene_h5, events=False)
    scene.require("frames", path=str(scene_h5), hint="the blurry frames are measured")
    y = luma_dn(scene.frames.blurry)  # type: ignore[union-attr]
    var = float(np.median(local_variance(y)))
    return {"width": y.shape[2], "height": y.shape[1], "frames": y.shape[0], "mean_dn": float(y.mean()),
            "median_local_var_dn2": var, "var_over_c2": var / C2_DN2}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results", nargs="+", type=Path, help="scene results folders (each with scene.h5)")
    add_out_argument(ap)
    args = ap.parse_args()
    data, rows = {}, []
    for r in args.results:
        m = scene_light(r / "scene.h5")
        data[r.name] = m
        rows.append([r.name, f"{m['width']}×{m['height']}", str(m["frames"]), fixed(m["mean_dn"], 1),
                     fixed(m["median_local_var_dn2"], 1), fixed(m["var_over_c2"], 3)])  # fmt: skip
        print(rows[-1], flush=True)
    body = (
        "Blurry training frames, luma in DN: the mean, and the median over pixels of the local variance in SSIM's "
        f"11-pixel Gaussian window (σ = 1.5), against SSIM's C2 = {C2_DN2:.1f} DN² at data range 1 "
        "(`bench/frame_light.py`).\n\n"
        + table(["scene", "size", "frames", "mean DN", "median local variance (DN²)", "÷ C2"], rows)
        + "\n"
    )
    write_section("frame-light", "How much texture the blur term's SSIM sees (issue 43)", body, data=data,
                  out=args.out)  # fmt: skip
    print(body)


if __name__ == "__main__":
    main()
