"""The paper's row on blur made as E²NeRF made its data, beside the default suite (issue 45): two suite ledgers
(``bench/suite_ledger.py``), the same six scenes, the same runs, compared run by run and scene by scene.

Reported from the ledgers' ``metrics.json`` files (novel-view PSNR, dB): each run's mean over the scenes both
ledgers have, and per scene the figures the issue asks about: ``eigs`` (the paper's EiGS) − ``edi-3dgs``; Table II's
four rows (``eigs-a``, ``eigs-b``, ``eigs-minus``, ``eigs``), their spread (best − worst) and order; the ladder's
blur-target rung (``eigs-zero-disc`` − ``eigs-zero``: the discrete blur target); ``e2gs`` and ``eigs+`` against
``edi-3dgs``. A scene that a run lacks in a ledger is left out of that figure's mean and said so.

Run: ``.venv/bin/python bench/e2nerf_blur_compare.py [--suite docs/suite] [--e2b docs/e2nerf_blur] [--out DIR]``;
the section is ``e2nerf-blur-compare`` in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import add_out_argument, table, write_section  # noqa: E402
from eigs.tables.collect import RunSummary, summarise  # noqa: E402

# the runs of config/e2nerf_blur.yaml (issue 45's list)
RUNS = ("edi-3dgs", "e2gs", "eigs-a", "eigs-b", "eigs-minus", "eigs", "eigs-zero", "eigs-zero-disc", "eigs+", "oracle")
TABLE2 = {"eigs-a": "(a)", "eigs-b": "(b)", "eigs-minus": "Ours−", "eigs": "Ours"}
PAPER_TABLE2 = {"eigs-a": 24.10, "eigs-b": 25.50, "eigs-minus": 24.52, "eigs": 28.21}  # the paper's Table II PSNR


def read_ledger(ledger: Path) -> dict[str, RunSummary]:
    """Run → summary over the ledger's scenes (``LEDGER/results/<scene>/b*/eval/<run>/metrics.json``)."""
    files = sorted(ledger.glob("results/*/b*/eval/*/metrics.json"))
    if not files:
        raise SystemExit(f"e2nerf_blur_compare.py: {ledger}: no metrics.json under results/*/b*/eval/")
    return summarise(files)


def psnrs(runs: dict[str, RunSummary]) -> dict[str, dict[str, float]]:
    """Run → scene → novel-view PSNR, for every run of :data:`RUNS` ({} for a run the ledger lacks)."""
    return {run: runs[run].scene_values("psnr") if run in runs else {} for run in RUNS}


def diff(ps: dict[str, dict[str, float]], a: str, b: str, scene: str) -> float:
    return ps[a][scene] - ps[b][scene] if scene in ps[a] and scene in ps[b] else math.nan


def order(values: dict[str, float]) -> str:
    """Table II's rows by PSNR, best first: ``Ours > (b) > …``."""
    return " > ".join(TABLE2[k] for k in sorted(values, key=values.get, reverse=True))


def fmt(v: float, signed: bool = True) -> str:
    return "–" if not math.isfinite(v) else (f"{v:+.2f}" if signed else f"{v:.2f}")


def mean(values: list[float]) -> float:
    finite = [v for v in values if math.isfinite(v)]
    return float(np.mean(finite)) if finite else math.nan


def compare(suite: dict[str, RunSummary], e2b: dict[str, RunSummary]) -> dict:
    """Every figure of the section, per ledger and scene (NaN where a run is missing)."""
    scenes = sorted({s for r in e2b.values() for s in r.scenes} & {s for r in suite.values() for s in r.scenes})
    by_ledger = {"suite": psnrs(suite), "e2b": psnrs(e2b)}
    out: dict = {"scenes": scenes, "ledgers": {}}
    for name, ps in by_ledger.items():
        per: dict[str, dict[str, float]] = {}
        for s in scenes:
            t2 = {k: ps[k][s] for k in TABLE2 if s in ps[k]}
            per[s] = {
                "eigs-edi": diff(ps, "eigs", "edi-3dgs", s),
                "e2gs-edi": diff(ps, "e2gs", "edi-3dgs", s),
                "eigs+-edi": diff(ps, "eigs+", "edi-3dgs", s),
                "eigs+-oracle": diff(ps, "eigs+", "oracle", s),
                "rung": diff(ps, "eigs-zero-disc", "eigs-zero", s),
                "t2_spread": max(t2.values()) - min(t2.values()) if len(t2) == len(TABLE2) else math.nan,
                "t2_order": order(t2) if len(t2) == len(TABLE2) else "",
            }
        means = {run: mean([ps[run].get(s, math.nan) for s in scenes]) for run in RUNS}
        counts = {run: sum(s in ps[run] for s in scenes) for run in RUNS}
        t2_means = {k: means[k] for k in TABLE2 if counts[k] == len(scenes)}
        out["ledgers"][name] = {
            "per_scene": per,
            "means": means,
            "counts": counts,
            "t2_order": order(t2_means) if len(t2_means) == len(TABLE2) else "",
            "t2_spread": max(t2_means.values()) - min(t2_means.values()) if len(t2_means) == len(TABLE2) else math.nan,
        }
    # E²NeRF − default per run: the mean over the scenes both ledgers have that run on (paired by scene)
    a, b = by_ledger["e2b"], by_ledger["suite"]
    out["paired"] = {run: mean([a[run][s] - b[run][s] for s in scenes if s in a[run] and s in b[run]]) for run in RUNS}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--suite", type=Path, default=Path("docs/suite"), help="the default suite's ledger")
    ap.add_argument("--e2b", type=Path, default=Path("docs/e2nerf_blur"), help="the E²NeRF-blur suite's ledger")
    add_out_argument(ap)
    args = ap.parse_args()
    got = compare(read_ledger(args.suite), read_ledger(args.e2b))
    scenes, led = got["scenes"], got["ledgers"]
    n = len(scenes)

    def cell(name: str, run: str) -> str:
        c = led[name]["counts"][run]
        return fmt(led[name]["means"][run], signed=False) + ("" if c == n else f" ({c} of {n})")

    rows = [[f"`{r}`", cell("suite", r), cell("e2b", r), fmt(got["paired"][r])] for r in RUNS]
    keys = [("eigs-edi", "`eigs` − `edi-3dgs`"), ("t2_spread", "Table II spread"), ("rung", "blur-target rung"),
            ("e2gs-edi", "`e2gs` − `edi-3dgs`"), ("eigs+-edi", "`eigs+` − `edi-3dgs`"),
            ("eigs+-oracle", "`eigs+` − oracle")]  # fmt: skip
    per_rows = []
    for s in [*scenes, "mean"]:
        row = [s]
        for k, _ in keys:
            for name in ("suite", "e2b"):
                if s == "mean":
                    v = led[name]["t2_spread"] if k == "t2_spread" else mean(
                        [led[name]["per_scene"][x][k] for x in scenes])
                else:
                    v = led[name]["per_scene"][s][k]
                row.append(fmt(v, signed=k != "t2_spread"))
        per_rows.append(row)
    header = ["scene"] + [f"{label} {name}" for _, label in keys for name in ("suite", "e2b")]
    orders = [[s, led["suite"]["per_scene"][s]["t2_order"] or "–", led["e2b"]["per_scene"][s]["t2_order"] or "–"]
              for s in scenes] + [["mean", led["suite"]["t2_order"] or "–", led["e2b"]["t2_order"] or "–"]]  # fmt: skip
    paper = " > ".join(TABLE2[k] for k in sorted(PAPER_TABLE2, key=PAPER_TABLE2.get, reverse=True))
    body = (
        f"Ledgers `{args.suite}` (the default suite: blur the mean of 81 sub-frames) and `{args.e2b}` (E²NeRF's "
        "synthesis: the mean of 17 renders, `blur_synthesis: e2nerf`), the same six scenes (shake 1.25, 128×96, "
        "EDI + COLMAP poses of each suite's own frames) and budgets. Novel-view PSNR (dB). Means over the scenes; a "
        "run missing on some scenes says on how many.\n\n"
        + table(["run", "default suite", "E²NeRF blur", "E²NeRF − default (paired by scene)"], rows)
        + "\n\nPer scene, each figure on the default suite and on E²NeRF's blur (Table II spread: best − worst of "
        "its four rows; blur-target rung: `eigs-zero-disc` − `eigs-zero`; the mean row's spread is that of the "
        "rows' means):\n\n"
        + table(header, per_rows)
        + f"\n\nTable II's order (the paper: {paper}, spread "
        f"{max(PAPER_TABLE2.values()) - min(PAPER_TABLE2.values()):.2f} dB):\n\n"
        + table(["scene", "default suite", "E²NeRF blur"], orders)
    )
    write_section("e2nerf-blur-compare", "The paper's row on E²NeRF's blur against the default suite (issue 45)",
                  body, data=got, out=args.out)
    print(body)


if __name__ == "__main__":
    main()
