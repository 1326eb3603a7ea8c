"""Does BRISQUE rank the methods as PSNR does? Rank correlations over the methods on the scenes that went through the
real-data path with a hidden ground truth (``metrics.json`` ``hidden_ground_truth``; ``config/davis346.yaml``), where
both are known. The paper's real-data protocol (BRISQUE only) rests on that agreement.

Per scene: Spearman's rho (Pearson correlation of average ranks) and Kendall's tau-b between the methods' BRISQUE
ranking (lower is better) and their PSNR ranking (novel views, higher is better), over the evaluated Gaussian runs
(``n_gaussians`` set) except the oracle; +1: the same order, −1: reversed. Overall: the mean of the defined per-scene
values, and the coefficients of the methods' scene means (the order Table I shows). A coefficient is undefined (NaN,
printed "–" with the reason) with fewer than two methods or when either ranking is all tied.
"""

from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eigs.tables.collect import RunSummary
from eigs.util.atomic import atomic_path

NAME = "brisque_rank"
TITLE = ("BRISQUE against PSNR: rank agreement over the methods (simulated recordings through the real-data path, "
         "ground truth hidden from training)")  # fmt: skip


def average_ranks(x: np.ndarray) -> np.ndarray:
    """Ranks 1..n of ``x`` (ascending), ties sharing the mean of their positions."""
    x = np.asarray(x, dtype=np.float64)
    order = np.argsort(x, kind="mergesort")
    ranks = np.empty(x.size, dtype=np.float64)
    sx = x[order]
    start = 0
    for end in range(1, x.size + 1):
        if end == x.size or sx[end] != sx[start]:
            ranks[order[start:end]] = 0.5 * (start + end - 1) + 1.0
            start = end
    return ranks


def _undefined(x: np.ndarray, y: np.ndarray) -> str:
    """Why a rank correlation of ``x`` and ``y`` is undefined ("" when it is defined)."""
    if x.size != y.size:
        raise ValueError(f"lengths differ: {x.size} and {y.size}")
    if x.size < 2:
        return f"{x.size} method(s)"
    if np.all(x == x[0]) or np.all(y == y[0]):
        return "all tied"
    return ""


def spearman(x: np.ndarray, y: np.ndarray) -> tuple[float, str]:
    """Spearman's rho with average ranks for ties; (NaN, reason) when undefined."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    why = _undefined(x, y)
    if why:
        return math.nan, why
    rx, ry = average_ranks(x), average_ranks(y)
    rx, ry = rx - rx.mean(), ry - ry.mean()
    return float(np.clip(rx @ ry / math.sqrt((rx @ rx) * (ry @ ry)), -1.0, 1.0)), ""


def kendall_tau_b(x: np.ndarray, y: np.ndarray) -> tuple[float, str]:
    """Kendall's tau-b (ties in either variable corrected); (NaN, reason) when undefined."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    why = _undefined(x, y)
    if why:
        return math.nan, why
    i, j = np.triu_indices(x.size, k=1)
    sx, sy = np.sign(x[i] - x[j]), np.sign(y[i] - y[j])
    s = float(np.sum(sx * sy))  # concordant − discordant
    nx, ny = float(np.count_nonzero(sx)), float(np.count_nonzero(sy))  # pairs untied in x, in y
    return float(np.clip(s / math.sqrt(nx * ny), -1.0, 1.0)), ""


@dataclass
class AgreementRow:
    """One line of the table: a scene, or an overall value (``scene`` names which)."""

    scene: str
    n_methods: int
    rho: float
    tau: float
    note: str = ""
    methods: tuple[str, ...] = ()


def _agreement(scene: str, brisque: dict[str, float], psnr: dict[str, float]) -> AgreementRow:
    methods = tuple(sorted(set(brisque) & set(psnr)))
    # agreement of the two "better" orders: lower BRISQUE is better, higher PSNR is better
    b = -np.array([brisque[m] for m in methods])
    p = np.array([psnr[m] for m in methods])
    rho, why = spearman(b, p)
    tau, _ = kendall_tau_b(b, p)
    return AgreementRow(scene, len(methods), rho, tau, why, methods)


def hidden_truth_scenes(runs: dict[str, RunSummary]) -> list[str]:
    """The scenes some run evaluated with ``hidden_ground_truth`` set, sorted."""
    return sorted({s for r in runs.values() for s, d in r.per_scene.items() if d.get("hidden_ground_truth")})


def ranked_runs(runs: dict[str, RunSummary]) -> list[RunSummary]:
    """The runs compared: Gaussian methods (``n_gaussians`` set on some scene), the oracle excluded."""
    return [r for _, r in sorted(runs.items()) if r.method != "oracle"
            and any(d.get("n_gaussians") is not None for d in r.per_scene.values())]  # fmt: skip


def _value(doc: dict, group: str, key: str) -> float | None:
    v = doc["metrics"].get(group, {}).get(key)
    return float(v) if v is not None and math.isfinite(float(v)) else None


def agreement_rows(runs: dict[str, RunSummary]) -> list[AgreementRow]:
    """Per hidden-ground-truth scene, then ``mean over scenes`` and ``scene means``; [] when there is no such
    scene."""
    scenes = hidden_truth_scenes(runs)
    if not scenes:
        return []
    cmp = ranked_runs(runs)
    out: list[AgreementRow] = []
    means: dict[str, dict[str, list[float]]] = {"brisque": {}, "psnr": {}}
    for scene in scenes:
        b: dict[str, float] = {}
        p: dict[str, float] = {}
        for r in cmp:
            d = r.per_scene.get(scene)
            if d is None or not d.get("hidden_ground_truth"):
                continue
            vb, vp = _value(d, "all", "brisque"), _value(d, "novel", "psnr")
            if vb is not None and vp is not None:
                b[r.run], p[r.run] = vb, vp
                means["brisque"].setdefault(r.run, []).append(vb)
                means["psnr"].setdefault(r.run, []).append(vp)
        out.append(_agreement(scene, b, p))
    defined = [r for r in out if math.isfinite(r.rho)]
    n = max((r.n_methods for r in out), default=0)
    if defined:
        rho = float(np.mean([r.rho for r in defined]))
        tau = float(np.mean([r.tau for r in defined if math.isfinite(r.tau)]))
        note = f"{len(defined)} of {len(out)} scenes defined"
    else:
        rho, tau, note = math.nan, math.nan, "no scene defined"
    out.append(AgreementRow("mean over scenes", n, rho, tau, note))
    # Table I's order: each method's mean over the scenes it has (BRISQUE and PSNR on the same scenes)
    sm = _agreement("scene means", {k: float(np.mean(v)) for k, v in means["brisque"].items()},
                    {k: float(np.mean(v)) for k, v in means["psnr"].items()})  # fmt: skip
    out.append(sm)
    return out


def _num(v: float, decimals: int = 3) -> str:
    return "–" if not math.isfinite(v) else f"{v:+.{decimals}f}"


NOTE = (
    "rho: Spearman (average ranks); tau: Kendall tau-b; between the methods' BRISQUE order (lower better, all "
    "renders: training views and render path) and their novel-view PSNR order (higher better) on the same scene; +1 "
    "the same order, −1 reversed; methods: the evaluated Gaussian runs except the oracle. `mean over scenes`: the "
    "mean of the defined per-scene values; `scene means`: the coefficients of the methods' means over the scenes "
    "(Table I's order). – : undefined (fewer than 2 methods, or one ranking all tied)."
)


def to_markdown(rows: list[AgreementRow]) -> str:
    lines = [f"**{TITLE}**", "", "| scene | methods | Spearman rho | Kendall tau-b | note |", "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r.scene} | {r.n_methods} | {_num(r.rho)} | {_num(r.tau)} | {r.note} |")
    lines += ["", NOTE, ""]
    return "\n".join(lines)


def to_csv(rows: list[AgreementRow]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["scene", "n_methods", "spearman_rho", "kendall_tau_b", "note", "methods"])
    for r in rows:
        w.writerow([r.scene, r.n_methods, "" if not math.isfinite(r.rho) else repr(r.rho),
                    "" if not math.isfinite(r.tau) else repr(r.tau), r.note, " ".join(r.methods)])  # fmt: skip
    return buf.getvalue()


def write_agreement(rows: list[AgreementRow], out_dir: str | os.PathLike) -> list[Path]:
    """Write ``brisque_rank.csv`` and ``.md`` into ``out_dir`` (atomically); returns the paths."""
    out = []
    for ext, text in (("csv", to_csv(rows)), ("md", to_markdown(rows))):
        p = Path(out_dir) / f"{NAME}.{ext}"
        with atomic_path(p) as tmp:
            tmp.write_text(text)
        out.append(p)
    return out
