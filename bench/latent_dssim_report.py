"""Which sharp-frame term for `eigs+`? (issue 43, part 4): the studies config/latent_dssim.yaml (six 128×96 scenes)
and config/latent_dssim_d346.yaml (the DAVIS346-like scenes), read from their ``metrics.json`` files.

Per scene, `eigs+` as configured and each candidate (``RUNS``: the latent term's weight, its D-SSIM, the SSIM's data
range), beside `edi-3dgs` and the oracle where they were run: novel-view PSNR (dB), SSIM, LPIPS, BRISQUE (training
views and path; lower is better), the high-frequency coherence (docs/metrics.md: the ground truth's detail
reproduced), Gaussians at the end and the training's CPU seconds (one thread; ``process_cpu_s`` of the run's
config.json: unlike its wall time, not inflated by other jobs on the machine). At 346×260 also the share of the
oracle's PSNR margin over `edi-3dgs` a run closes, (run − edi-3dgs) / (oracle − edi-3dgs), the issue's target being
70 %. Then per run and size the mean difference from `eigs+` over the scenes that have both.

Run: ``.venv/bin/python bench/latent_dssim_report.py [--results DIR ...] [--out DIR]`` (DIR: a results folder or a
suite ledger; default ``results``); the section is ``latent-dssim`` in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import fixed, results_roots, table, write_section  # noqa: E402

# the run names of the studies, in the order of the tables, and what each changes in eigs+
RUNS = {
    "edi-3dgs": "reference",
    "eigs+": "as configured (latent weight 0.5, L1)",
    "eigs+-ds": "D-SSIM in the latent term",
    "eigs+-dsr": "D-SSIM in the latent term, SSIM range 0.1",
    "eigs+-l2d": "latent weight 2 with the D-SSIM",
    "eigs+-ld": "latent weight 4 with the D-SSIM",
    "oracle": "reference",
}
CANDIDATES = ("eigs+-ds", "eigs+-dsr", "eigs+-l2d", "eigs+-ld")
METRICS = (("psnr", 2), ("ssim_3dgs", 4), ("lpips_alex", 3), ("coherence", 3))


def read(results: list[Path]) -> dict[tuple[str, str], dict]:
    """(scene, run) → metrics document, for the studies' runs (the first root that holds one wins)."""
    out: dict[tuple[str, str], dict] = {}
    for root in results:
        for path in sorted(root.glob("*/b4/eval/*/metrics.json")):
            scene, run = path.parts[-5], path.parts[-2]
            if run in RUNS and (scene, run) not in out:
                doc = json.loads(path.read_text())
                run_config = path.parents[2] / run / "config.json"  # <root>/<scene>/b4/<run>/config.json
                if run_config.is_file():
                    facts = json.loads(run_config.read_text()).get("run") or {}
                    doc["process_cpu_s"] = facts.get("process_cpu_s")
                    doc["resumed_at_step"] = facts.get("resumed_at_step") or 0
                out[(scene, run)] = doc
    return out


def value(doc: dict | None, key: str, group: str = "novel") -> float:
    """A novel-view metric (``brisque``: over all renders) of a metrics document; NaN when absent."""
    metrics = (doc or {}).get("metrics") or {}
    v = (metrics.get("all") or {}).get("brisque") if key == "brisque" else (metrics.get(group) or {}).get(key)
    return float(v) if v is not None else math.nan


def margin_closed(run: float, edi: float, oracle: float) -> float:
    """(run − edi-3dgs) / (oracle − edi-3dgs): the share of the oracle's margin a run closes (NaN without one)."""
    gap = oracle - edi
    return (run - edi) / gap if math.isfinite(gap) and gap > 0 and math.isfinite(run) else math.nan


def report(docs: dict[tuple[str, str], dict]) -> tuple[str, dict]:
    """The section's text and data."""
    body = [
        "Novel views against the ground truth: PSNR (dB), SSIM, LPIPS (alex), BRISQUE (training views and path; "
        "lower is better; 128×96 runs are not scored by it), coherence (docs/metrics.md), Gaussians at the end, "
        "the training's CPU seconds. 'margin': (run − `edi-3dgs`) / (oracle − `edi-3dgs`) in PSNR, where both were "
        "run. "
        "Studies config/latent_dssim.yaml and config/latent_dssim_d346.yaml, one seed, one thread a run; every row "
        "of a scene on the same SfM poses (one machine). Runs: "
        + "; ".join(f"`{r}` {what}" for r, what in RUNS.items() if what != "reference") + ".",
    ]
    data: dict[str, dict] = {}
    resumed: list[str] = []  # runs whose CPU seconds cover only the process that finished them
    for size, is_size in (("128×96", lambda s: not s.startswith("d346")), ("346×260", lambda s: s.startswith("d346"))):
        scenes = sorted({s for s, r in docs if is_size(s) and r in CANDIDATES})
        if not scenes:
            continue
        rows = []
        for scene in scenes:
            edi, oracle = value(docs.get((scene, "edi-3dgs")), "psnr"), value(docs.get((scene, "oracle")), "psnr")
            for run in RUNS:
                doc = docs.get((scene, run))
                if doc is None:
                    continue
                rec = {key: value(doc, key) for key, _ in METRICS} | {"brisque": value(doc, "brisque")}
                cpu = doc.get("process_cpu_s")
                if doc.get("resumed_at_step"):  # its last process's CPU only: not a training's cost
                    cpu = None
                    resumed.append(f"{scene} `{run}` resumed at step {doc['resumed_at_step']}")
                rec |= {"gaussians": doc.get("n_gaussians"), "cpu_s": float(cpu) if cpu is not None else math.nan,
                        "margin": margin_closed(rec["psnr"], edi, oracle)}  # fmt: skip
                data[f"{scene}/{run}"] = rec
                margin = fixed(100 * rec["margin"], 0) + (" %" if math.isfinite(rec["margin"]) else "")
                rows.append([scene, f"`{run}`", *(fixed(rec[k], d) for k, d in METRICS), fixed(rec["brisque"], 1),
                             f"{rec['gaussians']:,}" if rec["gaussians"] is not None else "–",
                             fixed(rec["cpu_s"], 0), margin])  # fmt: skip
        body += ["", f"**{size}**", "",
                 table(["scene", "run", "PSNR", "SSIM", "LPIPS", "coherence", "BRISQUE", "Gaussians", "CPU s",
                        "margin"], rows)]  # fmt: skip
        means = []
        for run in CANDIDATES:
            pairs = [(data[f"{s}/{run}"], data[f"{s}/eigs+"]) for s in scenes
                     if f"{s}/{run}" in data and f"{s}/eigs+" in data]  # fmt: skip
            if not pairs:
                continue
            diff = {k: sum(a[k] - b[k] for a, b in pairs) / len(pairs) for k, _ in METRICS}
            ratio = sum(a["cpu_s"] / b["cpu_s"] for a, b in pairs) / len(pairs)
            data[f"{size}/{run}-minus-eigs+"] = diff | {"train_ratio": ratio, "scenes": len(pairs)}
            means.append([f"`{run}`", str(len(pairs)), *(fixed(diff[k], d, sign=True) for k, d in METRICS),
                          fixed(ratio) + ("×" if math.isfinite(ratio) else "")])  # fmt: skip
        if means:
            headers = ["run", "scenes", "PSNR", "SSIM", "LPIPS", "coherence", "CPU s ratio"]
            title = f"Against `eigs+` at {size}, the mean over the scenes that have both:"
            body += ["", title, "", table(headers, means)]
    if resumed:
        body += ["", "CPU s left out (–) of runs resumed from a checkpoint, whose recorded CPU seconds are the last "
                 "process's only: " + "; ".join(resumed) + "."]  # fmt: skip
    return "\n".join(body), data


def main() -> None:
    args, roots = results_roots(argparse.ArgumentParser(description=__doc__.splitlines()[0]))
    text, data = report(read(roots))
    write_section("latent-dssim", "Which sharp-frame term for eigs+ (issue 43)", text, data, args.out)


if __name__ == "__main__":
    main()
