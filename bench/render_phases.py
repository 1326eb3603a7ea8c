"""What the renders of one multi-render step could share (issue 46, part 2): one render's forward split into its
phases on a scene's own artifacts.

Writes the "render-phases" section of docs/benchmarks.md. For each case (a scene's results folder and a Gaussian
count), the init cloud resampled as bench/train.py does is rendered from the first training camera, and the three
phases of the CPU forward are timed alone (median of ``--repeats`` calls, ``--threads`` threads): the projection
(per Gaussian: covariance, 2-D conic, extent, culling), the tile binning (pairs and their depth sort) and the
compositing. The B + 1 renders of an EiGS step differ only in the Gaussians' centres, so what they could share is at
most the per-Gaussian part of the projection and, where the displacements are sub-pixel, the binning; the
compositing is per render whatever is shared.

Run (a quiet machine): ``.venv/bin/python bench/render_phases.py --case results/d346-chair:6500
--case results/chair:10000 [--threads 2] [--repeats 30] [--out DIR]``.
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
from bench.train import resized_cloud  # noqa: E402
from eigs.render import _backend, _wrapper  # noqa: E402
from eigs.render.gaussians import SH_C0  # noqa: E402
from eigs.train.data import load_train_data  # noqa: E402


def median_ms(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times) * 1e3


def render_inputs(cloud, channels: int) -> tuple[torch.Tensor, ...]:  # noqa: ANN001
    """A GaussianCloud as the rasterizer takes it: means (N,3), unit quats (N,4), scales (N,3), opacities (N,) and the
    SH band 0 colour (N, channels) ≥ 0, as eigs.render.gaussians.sh_to_color; float32, contiguous."""
    means = torch.as_tensor(cloud.means, dtype=torch.float32).contiguous()
    quats = torch.nn.functional.normalize(torch.as_tensor(cloud.quats, dtype=torch.float32), dim=-1).contiguous()
    scales = torch.exp(torch.as_tensor(cloud.log_scales, dtype=torch.float32)).contiguous()
    opac = torch.sigmoid(torch.as_tensor(cloud.opacity, dtype=torch.float32).reshape(-1)).contiguous()
    colors = 0.5 + SH_C0 * torch.as_tensor(cloud.f_dc, dtype=torch.float32).reshape(len(means), -1)
    return means, quats, scales, opac, colors[:, :channels].clamp_min(0).contiguous()


def phases(results: Path, n: int, repeats: int) -> list[str]:
    """One row: image, Gaussians, pairs, project / bin / composite ms, the first two's share."""
    b = results / "b4"
    data = load_train_data(results / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    cloud = resized_cloud(data.init, n) if n > 0 else data.init
    c2w = data.c2w.reshape(-1, 4, 4)[0].double()
    cam = _wrapper.camera_list(torch.linalg.inv(c2w), data.K, torch.float32)
    means, quats, scales, opac, colors = render_inputs(cloud, data.channels)
    bg = data.background.float().contiguous()
    w, h = data.width, data.height
    ext = _backend.load()
    m2, con, dep, extent, radii = ext.project_fwd(means, quats, scales, opac, colors, cam, w, h)
    offs, ids = ext.isect_tiles(m2, extent, dep, radii, w, h, con, opac)
    t_proj = median_ms(lambda: ext.project_fwd(means, quats, scales, opac, colors, cam, w, h), repeats)
    t_bin = median_ms(lambda: ext.isect_tiles(m2, extent, dep, radii, w, h, con, opac), repeats)
    t_comp = median_ms(lambda: ext.rasterize_fwd(m2, con, colors, opac, extent, bg, offs, ids, w, h, 0), repeats)
    share = (t_proj + t_bin) / (t_proj + t_bin + t_comp)
    return [f"{results.name}", f"{w}×{h}", f"{len(means):,}", f"{ids.numel():,}", f"{t_proj:.2f}", f"{t_bin:.2f}",
            f"{t_comp:.2f}", f"{100 * share:.1f} %"]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", action="append", help="RESULTS:GAUSSIANS (repeatable; 0: the init cloud as it is)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=30)
    add_out_argument(ap)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rows = []
    for case in args.case or ["results/d346-chair:6500", "results/chair:10000"]:
        results, n = case.rsplit(":", 1)
        rows.append(phases(Path(results), int(n), args.repeats))
        print(rows[-1], flush=True)
    cols = ["scene", "image", "Gaussians", "pairs", "project ms", "bin ms", "composite ms", "project + bin share"]
    body = (
        f"One render's CPU forward by phase ({args.threads} threads, median of {args.repeats} calls; the init cloud "
        "resampled, the first training camera; `bench/render_phases.py`). An EiGS step's B + 1 renders could share "
        "at most the projection's per-Gaussian work and the binning; the compositing is per render.\n\n"
        + table(cols, rows) + "\n"
    )
    write_section("render-phases", "What the renders of a step could share (issue 46)", body, out=args.out)
    print(body)


if __name__ == "__main__":
    main()
