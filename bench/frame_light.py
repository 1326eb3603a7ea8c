"""How much of each scene's texture the blur term's SSIM can see (issue 43, part 4; docs/results.md "Why `eigs+`
renders smooth at 346×260").

Per scene, over its blurry training frames (BT.709 luma, 8-bit DN): the mean, and the median over pixels of the
local variance in SSIM's window against SSIM's constant C2 = (0.03 · 255)² = 58.5 DN² at data range 1
(:mod:`eigs.metrics.texture`). Where the local variance is far below C2, SSIM's contrast term is flat in the texture
and the blur term's D-SSIM barely asks for it; below ``DARK_TEXTURE`` × C2 the option ``latent_weight_dark`` of
EiGS takes over the sharp-frame term's weight.

Run: ``.venv/bin/python bench/frame_light.py results/chair results/d346-chair … [--out DIR]`` (each argument a
scene's results folder holding ``scene.h5``); the section is ``frame-light`` in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, fixed, table, write_section  # noqa: E402
from eigs.metrics.texture import DARK_TEXTURE, SSIM_C2, local_variance, luma  # noqa: E402
from eigs.scene.file import read_scene  # noqa: E402

C2_DN2 = SSIM_C2 * 255.0**2  # 58.5 DN²

def scene_light(scene_h5: Path) -> dict[str, float]:
    """A scene's blurry frames: mean DN, median local variance (DN²) and its ratio to C2."""
    scene = read_scene(scene_h5, events=False)
    scene.require("frames", path=str(scene_h5), hint="the blurry frames are measured")
    y = luma(torch.from_numpy(scene.frames.blurry) / 255.0) * 255.0  # type: ignore[union-attr]  # (N, H, W) DN
    var = float(local_variance(y).median())
    return {"width": y.shape[2], "height": y.shape[1], "frames": y.shape[0], "mean_dn": float(y.mean()),
            "median_local_var_dn2": var, "var_over_c2": var / C2_DN2, "dark": var / C2_DN2 < DARK_TEXTURE}  # fmt: skip


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
                     fixed(m["median_local_var_dn2"], 1), fixed(m["var_over_c2"], 3),
                     "yes" if m["dark"] else "no"])  # fmt: skip
        print(rows[-1], flush=True)
    body = (
        "Blurry training frames, BT.709 luma in DN: the mean, and the median over pixels of the local variance in "
        f"SSIM's 11-pixel Gaussian window (σ = 1.5), against SSIM's C2 = {C2_DN2:.1f} DN² at data range 1 "
        f"(`bench/frame_light.py`, eigs.metrics.texture); 'dark': below {DARK_TEXTURE} × C2, where the option "
        "`latent_weight_dark` of EiGS applies.\n\n"
        + table(["scene", "size", "frames", "mean DN", "median local variance (DN²)", "÷ C2", "dark"], rows)
        + "\n"
    )
    write_section("frame-light", "How much texture the blur term's SSIM sees (issue 43)", body, data=data,
                  out=args.out)  # fmt: skip
    print(body)


if __name__ == "__main__":
    main()
