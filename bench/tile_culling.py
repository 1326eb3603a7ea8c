"""The binning's tile culling against the whole-box binning, one render at a time (issue 46).

Writes the "tile-culling" section of docs/benchmarks.md. For each case (a scene's results folder and a Gaussian
count; the init cloud resampled as bench/train.py does), every third training view is rendered both ways in one
process, interleaved: the binning with and without the culling (``isect_tiles`` given or not given the conics and
opacities), then the compositing forward and backward on each binning (median of ``--repeats`` calls each,
``--threads`` threads, random cotangents). The two binnings give bit-identical renders and gradients
(tests/render/test_tile_culling.py), so the times are the whole difference.

Run (a quiet machine): ``.venv/bin/python bench/tile_culling.py --case results/d346-chair:6500
--case results/chair:10000 [--threads 2] [--repeats 9] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from bench.render_phases import median_ms, render_inputs  # noqa: E402
from bench.train import resized_cloud  # noqa: E402
from eigs.render import _backend, _wrapper  # noqa: E402
from eigs.train.data import load_train_data  # noqa: E402


def one_binning(C, proj, colors, opac, bg, w: int, h: int, extra: tuple, v_image, v_alpha,  # noqa: ANN001
                repeats: int) -> dict[str, float]:  # fmt: skip
    """Pairs and bin / forward / backward ms of one view with one binning (``extra``: () or (conics, opacities))."""
    m2, con, dep, ext, radii = proj
    t_bin = median_ms(lambda: C.isect_tiles(m2, ext, dep, radii, w, h, *extra), repeats)
    offs, ids = C.isect_tiles(m2, ext, dep, radii, w, h, *extra)
    _, _, trans, last, work = C.rasterize_fwd(m2, con, colors, opac, ext, bg, offs, ids, w, h, 0)
    t_fwd = median_ms(lambda: C.rasterize_fwd(m2, con, colors, opac, ext, bg, offs, ids, w, h, 0), repeats)
    t_bwd = median_ms(lambda: C.rasterize_bwd(m2, con, colors, opac, ext, bg, offs, ids, w, h, trans, last, work,
                                              v_image, v_alpha, 0), repeats)  # fmt: skip
    return {"pairs": float(ids.numel()), "bin": t_bin, "fwd": t_fwd, "bwd": t_bwd}


def compare(results: Path, n: int, repeats: int) -> dict[str, float]:
    """Mean over the views of pairs and bin / forward / backward ms, per binning ("whole", "culled")."""
    b = results / "b4"
    data = load_train_data(results / "scene.h5", b / "edi.h5", b / "sfm", b / "init.ply")
    cloud = resized_cloud(data.init, n) if n > 0 else data.init
    C = _backend.load()
    means, quats, scales, opac, colors = render_inputs(cloud, data.channels)
    bg = data.background.float().contiguous()
    w, h = data.width, data.height
    views = range(0, data.c2w.shape[0], 3)
    sums = {f"{k} {m}": 0.0 for k in ("whole", "culled") for m in ("pairs", "bin", "fwd", "bwd")}
    for v in views:
        cam = _wrapper.camera_list(torch.linalg.inv(data.c2w[v, 0].double()), data.K, torch.float32)
        m2, con, dep, ext, radii = C.project_fwd(means, quats, scales, opac, colors, cam, w, h)
        g = torch.Generator().manual_seed(v)
        v_image = torch.randn(h, w, colors.shape[1], generator=g)
        v_alpha = torch.randn(h, w, generator=g)
        for _ in range(2):  # interleaved twice
            for kind, extra in (("whole", ()), ("culled", (con, opac))):
                got = one_binning(C, (m2, con, dep, ext, radii), colors, opac, bg, w, h, extra, v_image, v_alpha,
                                  repeats)  # fmt: skip
                for m, x in got.items():
                    sums[f"{kind} {m}"] += x
    k = 2 * len(views)
    return {key: x / k for key, x in sums.items()} | {"width": w, "height": h, "gaussians": len(means)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", action="append", required=True, help="RESULTS:GAUSSIANS (0: the init cloud as it is)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=9)
    add_out_argument(ap)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    rows, measured = [], {}
    for case in args.case:
        path, n = case.rsplit(":", 1)
        m = compare(Path(path), int(n), args.repeats)
        measured[case] = m
        whole = m["whole bin"] + m["whole fwd"] + m["whole bwd"]
        culled = m["culled bin"] + m["culled fwd"] + m["culled bwd"]
        rows.append([Path(path).name, f"{m['width']}×{m['height']}", f"{m['gaussians']:,}",
                     f"{m['whole pairs']:,.0f} → {m['culled pairs']:,.0f}",
                     f"{100 * (1 - m['culled pairs'] / m['whole pairs']):.1f} %",
                     f"{m['whole bin']:.2f} → {m['culled bin']:.2f}", f"{m['whole fwd']:.2f} → {m['culled fwd']:.2f}",
                     f"{m['whole bwd']:.2f} → {m['culled bwd']:.2f}", f"{culled / whole:.3f}"])  # fmt: skip
        print(rows[-1], flush=True)
    cols = ["scene", "image", "Gaussians", "pairs", "left out", "bin ms", "forward ms", "backward ms",
            "bin + fwd + bwd, culled / whole"]  # fmt: skip
    body = (
        f"One render's binning, compositing forward and backward, the whole-box binning against the culled one "
        f"(`bench/tile_culling.py`): every third training view, the init cloud resampled, {args.threads} threads, "
        f"median of {args.repeats} calls, the two interleaved twice per view; means over the views.\n\n"
        + table(cols, rows) + "\n"
    )
    write_section("tile-culling", "Tile culling in the binning (issue 46)", body,
                  data={"threads": args.threads, "cases": measured}, out=args.out)  # fmt: skip
    print(body)


if __name__ == "__main__":
    main()
