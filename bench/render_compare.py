"""Renders of several evaluations side by side, brightened, with the ground truth first: what the metrics of a
comparison look like (dark DAVIS346-like frames are unreadable at their own brightness).

Each ``LABEL=DIR`` is an evaluation folder (``eigs evaluate``'s output folder, holding ``renders/``); the ground
truth is the first folder's ``renders/gt_<group>/``. Every image is multiplied by ``--gain`` and clipped to 8 bits,
the same for all, and labelled above.

Run: ``.venv/bin/python bench/render_compare.py --view 31 --out docs/figures/x.png "edi-3dgs=results/d346-chair/b4/
eval/edi-3dgs" "eigs+=…"`` [--group novel] [--gain 4]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from eigs.util.image import write_png

LABEL_PX = 16  # height of the label strip above each image


def load(path: Path) -> np.ndarray:
    """An 8-bit RGB render (H, W, 3); a clear error naming the file when it is missing."""
    if not path.is_file():
        raise SystemExit(f"render_compare.py: {path}: no such render")
    return np.asarray(Image.open(path).convert("RGB"))


def panel(image: np.ndarray, label: str, gain: float) -> np.ndarray:
    """``image`` × ``gain`` clipped to [0, 255], under a black strip with ``label``."""
    bright = np.clip(image.astype(np.float64) * gain, 0.0, 255.0).round().astype(np.uint8)
    strip = Image.new("RGB", (image.shape[1], LABEL_PX))
    ImageDraw.Draw(strip).text((4, 2), label, fill=(255, 255, 255))
    return np.concatenate([np.asarray(strip), bright], axis=0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="LABEL=DIR: an evaluation folder and its label")
    ap.add_argument("--view", type=int, required=True, help="the image index (the PNG's number)")
    ap.add_argument("--group", default="novel", help="the render group (novel, blur, novel_pose_opt, …)")
    ap.add_argument("--gain", type=float, default=4.0, help="brightness factor of every panel")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    runs = [r.split("=", 1) for r in args.runs]
    if any(len(r) != 2 for r in runs):
        raise SystemExit("render_compare.py: each run is LABEL=DIR")
    name = f"{args.view:04d}.png"
    first = Path(runs[0][1]) / "renders"
    panels = [panel(load(first / f"gt_{args.group}" / name), "ground truth", args.gain)]
    panels += [panel(load(Path(d) / "renders" / args.group / name), label, args.gain) for label, d in runs]
    write_png(args.out, np.concatenate(panels, axis=1))  # atomic; makes the folder
    print(f"wrote {args.out}: {len(panels)} panels of view {args.view} ({args.group}), ×{args.gain:g}")


if __name__ == "__main__":
    main()
