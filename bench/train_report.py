"""Summarise finished training runs into docs/results.md: per scene and method the final held-out PSNR (novel
views, blur views), the distance to `oracle`, the training time, the Gaussians, and the time-versus-PSNR curves
(docs/figures/train_curves.png).

Run: ``.venv/bin/python bench/train_report.py RUN_DIR [RUN_DIR …] [--title TEXT]`` (run folders of `eigs train`,
e.g. ``results/*/b4/*/``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import machine, table  # noqa: E402

DOCS = Path(__file__).resolve().parents[1] / "docs"


def load(run: Path) -> dict:
    doc = json.loads((run / "config.json").read_text())
    rows = list(csv.DictReader((run / "train_log.csv").open()))
    curve = [(int(r["step"]), float(r["wall_s"]), float(r["psnr_novel"]), float(r["psnr_blur"] or "nan"))
             for r in rows if r.get("psnr_novel")]  # fmt: skip
    return {"scene": doc["run"]["scene"], "method": doc["train"]["method"], "seconds": doc["run"]["train_seconds"],
            "n": doc["run"]["n_gaussians"], "curve": curve, "steps": doc["train"]["steps"]}  # fmt: skip


def plateau_time(curve: list[tuple[int, float, float, float]], tol: float = 0.3) -> float:
    """Seconds until the novel-view PSNR first comes within ``tol`` dB of its best value."""
    best = max(c[2] for c in curve)
    return next(c[1] for c in curve if c[2] >= best - tol)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--title", default="Training on the built-in scenes")
    ap.add_argument("--note", default="")
    args = ap.parse_args()
    runs = [load(r) for r in args.runs if (r / "config.json").exists()]
    by = defaultdict(dict)
    for r in runs:
        by[r["scene"]][r["method"]] = r
    methods = sorted({r["method"] for r in runs}, key=lambda m: (m != "3dgs", m != "edi-3dgs", m == "oracle", m))
    rows = []
    for scene in sorted(by):
        for m in methods:
            r = by[scene].get(m)
            if r is None:
                continue
            last = r["curve"][-1]
            oracle = by[scene].get("oracle")
            gap = last[2] - oracle["curve"][-1][2] if oracle else math.nan
            rows.append([scene, m, f"{last[2]:.2f}", f"{last[3]:.2f}", f"{gap:+.2f}", f"{r['seconds']:.0f}",
                         f"{plateau_time(r['curve']):.0f}", f"{r['n']:,}"])  # fmt: skip
    means = []
    for m in methods:
        vals = [by[s][m]["curve"][-1] for s in by if m in by[s]]
        secs = [by[s][m]["seconds"] for s in by if m in by[s]]
        if vals:
            means.append([m, len(vals), f"{sum(v[2] for v in vals) / len(vals):.2f}",
                          f"{sum(v[3] for v in vals) / len(vals):.2f}", f"{sum(secs) / len(secs):.0f}"])  # fmt: skip
    fig = DOCS / "figures" / "train_curves.png"
    fig.parent.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted(by)
    cols = min(3, len(scenes))
    nrows = math.ceil(len(scenes) / cols)
    f, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.2 * nrows), squeeze=False)
    for ax, scene in zip(axes.flat, scenes, strict=False):
        for m in methods:
            r = by[scene].get(m)
            if r:
                ax.plot([c[1] for c in r["curve"]], [c[2] for c in r["curve"]], label=m, marker=".", ms=3)
        ax.set_title(scene)
        ax.set_xlabel("training time (s)")
        ax.set_ylabel("novel-view PSNR (dB)")
        ax.grid(alpha=0.3)
    axes.flat[0].legend(fontsize=7)
    f.tight_layout()
    f.savefig(fig, dpi=110)
    md = (
        f"# Results\n\n## {args.title}\n\nMeasured on {machine()}. {args.note}\n\n"
        "Held-out PSNR of 8-bit renders (dB, mean over images): novel views, and blur views at their reference pose; "
        "`Δ oracle`: novel-view distance to the `oracle` run of the scene; `s`: training seconds (held-out "
        "evaluation excluded); `plateau s`: seconds until the novel-view PSNR came within 0.3 dB of its best.\n\n"
        "Means over scenes:\n\n"
        + table(["method", "scenes", "PSNR novel", "PSNR blur", "s"], means)
        + "\n\nPer scene:\n\n"
        + table(["scene", "method", "PSNR novel", "PSNR blur", "Δ oracle", "s", "plateau s", "Gaussians"], rows)
        + f"\n\n![time versus PSNR](figures/{fig.name})\n"
    )
    (DOCS / "results.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
