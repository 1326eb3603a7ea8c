"""Figures from evaluated runs (matplotlib, Agg): a qualitative grid per scene, time-versus-PSNR curves of every run
(``train_log.csv``) and a Pareto plot of training time against PSNR.

Qualitative grid: one blur view (the first of the scene's blur-view test images; a training view of scenes without
ground truth): the blurry input, the EDI latent frame k = 0 (the reference time, as the ground truth), each run's
render at that view (the PNG ``eigs evaluate`` scored) and the ground truth.
"""

from __future__ import annotations

import csv
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from eigs.artifacts import run as run_folder
from eigs.errors import EigsError
from eigs.tables.collect import RunSummary


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_png(path: Path) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a PNG (grey repeated)."""
    import cv2

    a = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if a is None:
        raise EigsError(path, "cannot read the image")
    if a.ndim == 2:
        return np.repeat(a[..., None], 3, axis=2)
    return np.ascontiguousarray(a[..., 2::-1])


def _rgb(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a)
    if a.ndim == 2:
        a = a[..., None]
    return np.repeat(a, 3, axis=2) if a.shape[2] == 1 else a


def run_config(doc: dict[str, Any]) -> dict[str, Any]:
    p = Path(doc["run_dir"]) / run_folder.CONFIG
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError) as err:
        raise EigsError(p, f"cannot read the run config ({err})") from None


def grid_view(doc: dict[str, Any], eval_dir: Path) -> tuple[str, str, int]:
    """(render set, file name, training view) of the view a scene's grid shows."""
    rows = list(csv.DictReader((eval_dir / "per_image.csv").open()))
    if doc["ground_truth"]:
        blur = [r for r in rows if r["set"] == "blur"]
        if blur:
            r = sorted(blur, key=lambda r: r["image"])[0]
            return "blur", r["image"], int(r["view"])
        r = sorted(rows, key=lambda r: r["image"])[0]
        return r["set"], r["image"], -1
    train = sorted((r for r in rows if r["set"] == "train"), key=lambda r: r["image"])
    if not train:
        raise EigsError(eval_dir, "no training-view renders to show")
    return "train", train[0]["image"], int(Path(train[0]["image"]).stem)


def qualitative_grid(scene: str, entries: list[tuple[str, Path, dict[str, Any]]], out: str | os.PathLike) -> None:
    """Grid for one scene. ``entries``: (run name, metrics.json path, metrics document), in column order."""
    from eigs.artifacts.edi import latent_png_name
    from eigs.scene import read_scene

    plt = _plt()
    name0, path0, doc0 = entries[0]
    eval0 = path0.parent
    kind, image, view = grid_view(doc0, eval0)
    cfg = run_config(doc0)
    panels: list[tuple[str, np.ndarray]] = []
    if view >= 0:
        sc = read_scene(cfg["inputs"]["scene"], events=False)
        if sc.frames is not None:
            panels.append(("blurry input", _rgb(sc.frames.blurry[view])))
        latent = Path(cfg["inputs"]["edi"]).parent / "latent" / latent_png_name(view, 0)
        if latent.exists():
            panels.append(("EDI latent (k = 0)", read_png(latent)))
    for run, path, _doc in entries:
        f = path.parent / "renders" / kind / image
        if f.exists():
            panels.append((run, read_png(f)))
    gt = eval0 / "renders" / f"gt_{kind}" / image
    if gt.exists():
        panels.append(("ground truth", read_png(gt)))
    h, w = panels[0][1].shape[:2]
    n = len(panels)
    nrows = math.ceil(n / 8)  # at most 8 panels a row, rows balanced
    cols = math.ceil(n / nrows)
    fig, axes = plt.subplots(nrows, cols, figsize=(2.6 * cols * w / max(h, w) + 0.2, 2.6 * nrows * h / max(h, w) + 0.5),
                             squeeze=False)  # fmt: skip
    for ax in axes.ravel():
        ax.axis("off")
    for ax, (title, img) in zip(axes.ravel(), panels, strict=False):
        ax.imshow(img, interpolation="nearest")
        ax.set_title(title, fontsize=8)
    fig.suptitle(f"{scene}: {'blur view' if kind == 'blur' else kind} {image}", fontsize=9)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def read_log(run_dir: str | os.PathLike) -> dict[str, np.ndarray]:
    """Columns of ``train_log.csv`` as float arrays (empty cells NaN)."""
    p = Path(run_dir) / run_folder.LOG
    try:
        rows = list(csv.DictReader(p.open()))
    except OSError as err:
        raise EigsError(p, f"cannot read the training log ({err})") from None
    if not rows:
        return {}
    return {k: np.array([float(r[k]) if r[k] not in ("", None) else np.nan for r in rows]) for k in rows[0]}


def time_curves(runs: dict[str, RunSummary], out: str | os.PathLike) -> None:
    """Held-out PSNR (novel views; blur views where a scene has no novel ones) against training seconds, one panel per
    scene with ground truth, one line per run."""
    plt = _plt()
    scenes = sorted({s for r in runs.values() for s in r.scenes if r.per_scene[s]["ground_truth"]})
    n = max(len(scenes), 1)
    cols = min(n, 3)
    fig, axes = plt.subplots(math.ceil(n / cols), cols, figsize=(4.2 * cols, 3.2 * math.ceil(n / cols)), squeeze=False)
    for ax in axes.ravel()[len(scenes):]:
        ax.axis("off")
    for ax, scene in zip(axes.ravel(), scenes, strict=False):
        for name in sorted(runs):
            doc = runs[name].per_scene.get(scene)
            if doc is None:
                continue
            log = read_log(doc["run_dir"])
            if not log:
                continue
            y = log.get("psnr_novel")
            if y is None or not np.isfinite(y).any():
                y = log.get("psnr_blur")
            if y is None:
                continue
            ok = np.isfinite(y) & np.isfinite(log["wall_s"])
            if ok.any():
                ax.plot(log["wall_s"][ok], y[ok], marker=".", ms=3, lw=1, label=name)
        ax.set_title(scene, fontsize=9)
        ax.set_xlabel("training time (s)")
        ax.set_ylabel("held-out PSNR (dB)")
        ax.grid(alpha=0.3)
    if scenes:
        axes.ravel()[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)


def pareto_front(points: list[tuple[float, float]]) -> list[int]:
    """Indices of points not dominated (no other point is both faster, x ≤, and better, y ≥, with one strict)."""
    front = []
    for i, (x, y) in enumerate(points):
        dominated = any(
            (x2 <= x and y2 >= y) and (x2 < x or y2 > y) for j, (x2, y2) in enumerate(points) if j != i
        )
        if not dominated:
            front.append(i)
    return sorted(front, key=lambda i: points[i][0])


def pareto_plot(runs: dict[str, RunSummary], out: str | os.PathLike) -> None:
    """Mean training seconds against mean novel-view PSNR per run (per scene as faint points), the Pareto front of the
    methods joined (the oracle, a star, is left out of it)."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    names, pts = [], []
    for name in sorted(runs):
        s = runs[name]
        x, y = s.values.get("time_s", math.nan), s.values.get("psnr", math.nan)
        per = [(d["train_seconds"], d["metrics"].get("novel", {}).get("psnr")) for d in s.per_scene.values()]
        per = [(a, b) for a, b in per if b is not None]
        if per:
            ax.scatter(*zip(*per, strict=True), s=8, alpha=0.25)
        if math.isfinite(x) and math.isfinite(y):
            names.append(name)
            pts.append((x, y))
    oracle = [runs[n].method == "oracle" for n in names]
    for (x, y), name, up in zip(pts, names, oracle, strict=True):
        ax.scatter([x], [y], s=60 if up else 30, color="k", marker="*" if up else "o")
        ax.annotate(name + (" (upper bound)" if up else ""), (x, y), fontsize=7, xytext=(3, 3),
                    textcoords="offset points")  # fmt: skip
    # the oracle trains on the sharp ground truth: an upper bound, not a competitor on the front
    methods = [i for i, up in enumerate(oracle) if not up]
    front = [methods[i] for i in pareto_front([pts[i] for i in methods])]
    if front:
        ax.plot([pts[i][0] for i in front], [pts[i][1] for i in front], "r--", lw=1, label="Pareto front (methods)")
        ax.legend(fontsize=7)
    ax.set_xscale("log")
    ax.set_xlabel("training time per scene (s, mean)")
    ax.set_ylabel("novel-view PSNR (dB, mean over scenes)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=120)
    plt.close(fig)
