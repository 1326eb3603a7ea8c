"""How far apart the blur syntheses are on the built-in scenes (docs/synthetic.md, "Blur synthesis"): per scene, the
PSNR between 8-bit blurry frames made by ``average`` (all sub-frames), ``e2nerf`` (17 renders) and the paper's
5-sample blur model (the mean of the B + 1 = 5 renders at the latent times, EiGS Eq. 2), on the first views of the
default suite's scenes (shake 1.25). Renders the exposures only (no events).

    .venv/bin/python bench/blur_synthesis.py [--views 6] [SCENE ...]
"""

from __future__ import annotations

import argparse

import numpy as np

from eigs.synth.blur import exposure_mean
from eigs.synth.generate import build_path, intrinsics
from eigs.synth.raycast import RayCaster
from eigs.synth.scenes import get_spec, resolve_params
from eigs.util.image import to_uint8

SUITE = ("blocks", "chair", "tree", "dish", "spheres", "drums")


def psnr_u8(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR (dB) between two linear images (any shape, [0, 1]) after 8-bit rounding."""
    d = to_uint8(a).astype(np.float64) - to_uint8(b).astype(np.float64)
    return float(10 * np.log10(255.0**2 / np.mean(d**2)))


def exposure_blurs(name: str, views: int) -> dict[str, np.ndarray]:
    """(views, H, W, 3) float64 linear blurry frames of scene ``name`` (shake 1.25, its seed's shake as the
    generator draws it) by each synthesis: ``average``, ``e2nerf`` and ``five`` (the 5 latent renders)."""
    p = resolve_params(name, ("bench", {"shake": 1.25, "n_train": views, "n_novel": 0}))
    spec = get_spec(name)
    caster = RayCaster(spec.build(), background=spec.background, lighting=spec.lighting,
                       texture_size=p["texture_size"])
    root = np.random.default_rng(p["seed"])
    rng_shake = np.random.default_rng(root.bit_generator.seed_seq.spawn(2)[0])  # as eigs.synth.generate draws it
    path, _ = build_path(p, spec, rng_shake)
    K = intrinsics(p["width"], p["height"], p["fov_deg"])
    out: dict[str, list[np.ndarray]] = {"average": [], "e2nerf": [], "five": []}
    step = p["subframes"] // p["n_bins"]
    for v in range(views):
        frames = caster.render(path(path.timeline.exposure_frame_times(v)), K, p["width"], p["height"],
                               supersample=p["supersample"]).rgb
        out["average"].append(exposure_mean(frames, "average"))
        out["e2nerf"].append(exposure_mean(frames, "e2nerf"))
        out["five"].append(frames[::step].astype(np.float64).mean(axis=0))
    return {k: np.stack(v) for k, v in out.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", default=list(SUITE))
    ap.add_argument("--views", type=int, default=6)
    args = ap.parse_args()
    print("| scene | e2nerf vs average | 5 latent renders vs average | 5 latent renders vs e2nerf |")
    print("|---|---|---|---|")
    rows = []
    for name in args.scenes:
        b = exposure_blurs(name, args.views)
        row = (psnr_u8(b["e2nerf"], b["average"]), psnr_u8(b["five"], b["average"]), psnr_u8(b["five"], b["e2nerf"]))
        rows.append(row)
        print(f"| {name} | " + " | ".join(f"{x:.2f}" for x in row) + " |", flush=True)
    print("| mean | " + " | ".join(f"{x:.2f}" for x in np.mean(rows, axis=0)) + " |")


if __name__ == "__main__":
    main()
