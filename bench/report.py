"""Assemble the benchmark report from one `bench` run: every section (``DIR/NAME.md``) and its measurements
(``DIR/NAME.json``) written by the bench scripts with ``--out DIR``, plus an overview with figures (time against
error over the knobs each bench sweeps, with the Pareto front, and times as ratios to a reference measured in the
same run) and the table of what the workflow skips when a scene does not need it.

Run by the workflow's `bench` target (rules/bench.smk): ``.venv/bin/python bench/report.py results/bench -o
docs/benchmarks.md --figures docs/figures [--quick] [--facts JSON]``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import table  # noqa: E402

# Sections in the order of the pipeline; a section missing from the run is left out.
SECTIONS = ["ingest", "synth", "edi", "sfm", "rasterizer", "train-step", "train-step-methods", "train-step-malloc",
            "metrics"]
FIGURES = ["edi", "sfm", "rasterizer", "train", "skips"]  # docs/figures/bench_<name>.png
TRAIN_STEPS_DEFAULT = 3000  # eigs.train.config.TrainConfig.steps; read from there when importable


def load(d: Path, name: str) -> dict | None:
    p = d / f"{name}.json"
    return json.loads(p.read_text()) if p.exists() else None


def pareto(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The points no other point beats in both coordinates (both minimised), sorted by the first."""
    front: list[tuple[float, float]] = []
    for x, y in sorted(points):
        if not front or y < front[-1][1]:
            front.append((x, y))
    return front


def fmt(x: float | None, spec: str = ".3g") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def mean(xs: list[float]) -> float | None:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return sum(xs) / len(xs) if xs else None


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def empty_figure(path: Path, what: str) -> None:
    """A figure that says the run measured nothing for it (the workflow declares every figure)."""
    plt = _plt()
    f, ax = plt.subplots(figsize=(4, 1.5))
    ax.axis("off")
    ax.text(0.5, 0.5, f"{what}: not measured in this run", ha="center", va="center")
    f.savefig(path, dpi=100)
    plt.close(f)


def finish_log_x_plot(plt, f, ax, fig: Path, xlabel: str, ylabel: str) -> None:
    """Log-scaled x axis, labels, legend and grid on ``ax``; save figure ``f`` to ``fig`` and close it."""
    ax.set_xscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    f.tight_layout()
    f.savefig(fig, dpi=110)
    plt.close(f)


def bar_figure(fig: Path, labels: list[str], values: list[float], notes: list[str], xlabel: str,
               size: tuple[float, float], log_x: bool = False) -> None:
    """Horizontal bars of ``values`` named by ``labels`` (first at the top), each annotated with its note."""
    plt = _plt()
    f, ax = plt.subplots(figsize=size)
    if labels:
        ax.barh(labels, values)
        for i, (v, note) in enumerate(zip(values, notes, strict=True)):
            ax.text(v, i, note, va="center", fontsize=7)
        if log_x:
            ax.set_xscale("log")
        ax.invert_yaxis()
    ax.set_xlabel(xlabel)
    f.tight_layout()
    f.savefig(fig, dpi=110)
    plt.close(f)


# --- EDI: latent frames' PSNR against time per scene, over B and mode --------------------------------------------
def edi_overview(doc: dict | None, fig: Path) -> str:
    rows = (doc or {}).get("data", {}) or {}
    rows = rows.get("runtime_error", [])
    if not rows:
        empty_figure(fig, "EDI")
        return ""
    ref = next((r for r in rows if r["bins"] == 4 and r["mode"] == "estimated"), rows[0])
    front = set(pareto([(r["time_s"], -r["latent_psnr"]) for r in rows]))
    plt = _plt()
    f, ax = plt.subplots(figsize=(5.5, 3.6))
    for mode, marker in (("estimated", "o"), ("e2nerf", "s")):
        pts = [r for r in rows if r["mode"] == mode]
        ax.scatter([r["time_s"] for r in pts], [r["latent_psnr"] for r in pts], marker=marker, label=mode)
        for r in pts:
            ax.annotate(f"B={r['bins']}", (r["time_s"], r["latent_psnr"]), fontsize=7, xytext=(3, 3),
                        textcoords="offset points")  # fmt: skip
    fx = sorted(front)
    ax.plot([p[0] for p in fx], [-p[1] for p in fx], "k--", lw=1, label="Pareto front")
    ax.axhline(mean([r["blurry_psnr"] for r in rows]), color="grey", lw=0.8, ls=":", label="blurry frame")
    finish_log_x_plot(plt, f, ax, fig, "EDI time per scene (s)", "latent-frame PSNR (dB)")
    trows = [[r["bins"], r["mode"], fmt(r["time_s"]), f"{r['time_s'] / ref['time_s']:.3g}×",
              f"{r['latent_psnr']:.2f}", "yes" if (r["time_s"], -r["latent_psnr"]) in front else ""]
             for r in sorted(rows, key=lambda r: (r["mode"], r["bins"]))]  # fmt: skip
    return (
        f"### EDI: latent frames, time against PSNR to the true sharp frames\n\n![EDI](figures/{fig.name})\n\n"
        f"Reference of the ratios: estimated mode at B = {ref['bins']} ({fmt(ref['time_s'])} s per scene).\n\n"
        + table(["B", "mode", "s / scene", "÷ ref", "latent PSNR (dB)", "Pareto"], trows)
    )


# --- SfM: time against ATE ----------------------------------------------------------------------------------------
def sfm_overview(doc: dict | None, fig: Path) -> str:
    data = (doc or {}).get("data") or {}
    pts = [("COLMAP, B = " + str(r["bins"]), r) for r in data.get("latent", []) + data.get("scaling", [])]
    pts += [("given poses", r) for r in data.get("given", []) if not r.get("error")]
    pts = [(k, r) for k, r in pts if r.get("ate_percent") is not None]
    if not pts:
        empty_figure(fig, "SfM")
        return ""
    colmap = [r for k, r in pts if k.startswith("COLMAP") and r["bins"] == data.get("bins")]
    ref_t = mean([r["time_s"] for r in colmap]) or pts[0][1]["time_s"]
    front = set(pareto([(r["time_s"], r["ate_percent"]) for _, r in pts]))
    plt = _plt()
    f, ax = plt.subplots(figsize=(5.5, 3.6))
    for label in sorted({k for k, _ in pts}):
        sel = [r for k, r in pts if k == label]
        ax.scatter([r["time_s"] for r in sel], [r["ate_percent"] for r in sel], label=label)
    fx = sorted(front)
    ax.plot([p[0] for p in fx], [p[1] for p in fx], "k--", lw=1, label="Pareto front")
    finish_log_x_plot(plt, f, ax, fig, "SfM time per scene (s)", "ATE (% of the extent)")
    trows = [[r["scene"], k, fmt(r["time_s"]), f"{r['time_s'] / ref_t:.3g}×", fmt(r["ate_percent"]),
              "yes" if (r["time_s"], r["ate_percent"]) in front else ""] for k, r in pts]  # fmt: skip
    return (
        f"### SfM: time against ATE\n\n![SfM](figures/{fig.name})\n\nReference of the ratios: the mean COLMAP time "
        f"per scene at B = {data.get('bins')} ({fmt(ref_t)} s). Given poses are the scene's ground truth (ATE 0 up "
        "to rounding).\n\n" + table(["scene", "poses", "s", "÷ ref", "ATE %", "Pareto"], trows)
    )


# --- rasterizer: time against size, error against the float64 reference -------------------------------------------
def rasterizer_overview(doc: dict | None, fig: Path) -> str:
    data = (doc or {}).get("data") or {}
    pipe, err = data.get("pipeline", []), data.get("error", [])
    if not pipe:
        empty_figure(fig, "rasterizer")
        return ""
    plt = _plt()
    f, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.4))
    lanes = [r["n_isects"] * 256 / 1e6 for r in pipe]
    for t in ("1t", "2t"):
        a1.plot(lanes, [r[f"fwd_{t}_ms"] + r[f"bwd_{t}_ms"] for r in pipe], "o-", label=f"fwd+bwd, {t[0]} thread(s)")
    for x, r in zip(lanes, pipe, strict=True):
        a1.annotate(f"{r['size']}²/{r['n'] // 1000}k", (x, r["fwd_1t_ms"] + r["bwd_1t_ms"]), fontsize=6,
                    xytext=(3, -8), textcoords="offset points")  # fmt: skip
    a1.set_xscale("log")
    a1.set_yscale("log")
    a1.set_xlabel("evaluated pair-lanes (M)")
    a1.set_ylabel("ms")
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3)
    if err:
        a2.plot([r["n"] for r in err], [r["max_abs"] for r in err], "o-", label="max |error|")
        a2.plot([r["n"] for r in err], [r["rms"] for r in err], "s-", label="RMS error")
        a2.set_yscale("log")
        a2.legend(fontsize=7)
    a2.set_xlabel("Gaussians (images " + ", ".join(f"{r['size']}²" for r in err) + ")")
    a2.set_ylabel("float32 image − float64 reference")
    a2.grid(alpha=0.3)
    f.tight_layout()
    f.savefig(fig, dpi=110)
    plt.close(f)
    ref = pipe[0]["fwd_2t_ms"] + pipe[0]["bwd_2t_ms"]
    trows = [[f"{r['size']}²", r["n"], fmt(r["fwd_2t_ms"] + r["bwd_2t_ms"]),
              f"{(r['fwd_2t_ms'] + r['bwd_2t_ms']) / ref:.3g}×", f"{r['scaling']:.2f}×"] for r in pipe]  # fmt: skip
    return (
        f"### Rasterizer: time against size, error against the float64 reference\n\n![rasterizer](figures/{fig.name})"
        f"\n\nReference of the ratios: {pipe[0]['size']}² with {pipe[0]['n']:,} Gaussians, 2 threads "
        f"({fmt(ref)} ms forward + backward).\n\n"
        + table(["image", "N", "fwd+bwd ms (2T)", "÷ ref", "2T scaling"], trows)
    )


# --- training step per method ---------------------------------------------------------------------------------------
def train_overview(doc: dict | None, fig: Path) -> str:
    rows = ((doc or {}).get("data") or {}).get("methods", [])
    if not rows:
        empty_figure(fig, "training step")
        return ""
    bar_figure(fig, [r["method"] for r in rows], [float(r["step_ms"]) for r in rows],
               [f" {r['ratio_3dgs']}" for r in rows], "one training step (ms)", (6, 0.3 * len(rows) + 1))
    return (
        f"### Training step of every method\n\n![training step](figures/{fig.name})\n\nRatios to the `3dgs` step of "
        f"the same run (one render); scene `{doc['data'].get('scene')}`, {doc['data'].get('threads')} threads."
    )


# --- skips ----------------------------------------------------------------------------------------------------------
def train_steps() -> int:
    try:
        from eigs.train.config import TrainConfig

        return int(TrainConfig().steps)
    except ImportError:  # the report itself needs no torch
        return TRAIN_STEPS_DEFAULT


def skips(d: Path, facts: dict, fig: Path) -> str:
    """The table (and figure) of every skip: time saved and quality changed, from this run's measurements."""
    edi, sfm, syn = load(d, "edi"), load(d, "sfm"), load(d, "synth")
    tm, met = load(d, "train-step-methods"), load(d, "metrics")
    edi_rows = ((edi or {}).get("data") or {}).get("runtime_error", [])
    edi_s = next((r["time_s"] for r in edi_rows if r["bins"] == 4 and r["mode"] == "estimated"), None)
    sd = (sfm or {}).get("data") or {}
    colmap_s = mean([r["time_s"] for r in sd.get("latent", [])])
    given_s = mean([r["time_s"] for r in sd.get("given", []) if not r.get("error")])
    colmap_ate = mean([r["ate_percent"] for r in sd.get("latent", []) if r.get("ate_percent") is not None])
    given_ate = mean([r["ate_percent"] for r in sd.get("given", []) if r.get("ate_percent") is not None])
    synth_s = mean([r["total_s"] for r in ((syn or {}).get("data") or [])])
    steps = {r["method"]: float(r["step_ms"]) for r in ((tm or {}).get("data") or {}).get("methods", [])}
    mets = {(r["metric"], r["how"]): r["wall_ms"] for r in ((met or {}).get("data") or [])}
    brisque_ms = next((v for (m, _h), v in mets.items() if m == "brisque"), None)
    n_steps = train_steps()

    def s(x: float | None) -> str:
        return fmt(x, ".3g") + " s" if x is not None else "not measured"

    def minus(a: float | None, b: float | None) -> float | None:
        return None if a is None or b is None else a - b

    rows: list[list[str]] = []
    saved: list[tuple[str, float]] = []

    def add(what: str, how: str, secs: float | None, unit: str, quality: str, source: str) -> None:
        rows.append([what, how, unit if secs is None and not source else s(secs) + unit, quality, source or "–"])
        if secs is not None and secs > 0:
            saved.append((what, secs))

    add(
        "ground-truth poses: no COLMAP mapping",
        f"`sfm_given` job instead of `sfm` ({facts.get('sfm_given', '?')} scene(s) of this config; given mode still "
        f"matches features along the known epipolar lines and triangulates): COLMAP {s(colmap_s)}, given {s(given_s)}",
        minus(colmap_s, given_s),
        " per scene and B",
        f"ATE {fmt(colmap_ate)} % → {fmt(given_ate)} % (exact poses)",
        "sfm.json (`--given`)",
    )
    ev_runs = facts.get("event_runs", {})
    unmeasured = sorted({r["method"] for r in ev_runs.values() if r["method"] not in steps})
    ev_train = None if unmeasured or not ev_runs else sum(
        steps[r["method"]] / 1e3 * (r["steps"] or n_steps) for r in ev_runs.values())  # fmt: skip
    names = ", ".join(f"`{name}`" for name in sorted(ev_runs)) or "none in this config"
    add(
        "scene without events (`events: false`): no event stages",
        f"an `edi_frames` job (`eigs edi --no-events`: every view passed through as sharp, no binning or threshold "
        f"search) instead of `edi`, and the training and evaluation jobs of the runs whose method needs events "
        f"(eigs.train.catalog; {names}) not scheduled on that scene ({facts.get('frames_only', '?')} such "
        f"scene(s) of this config): EDI {s(edi_s)}, their training "
        + (s(ev_train) if ev_train is not None else f"not measured ({', '.join(unmeasured) or 'no such run'})"),
        None if edi_s is None else edi_s + (ev_train or 0.0),
        " per scene (EDI at B = 4, estimated mode" + (" + the event runs' step time × steps)" if ev_train else ")"),
        "none for the runs kept (nothing to deblur with); the event runs have no result there (their table cells "
        "average the scenes they have)",
        "edi.json, train-step-methods.json, config",
    )
    one = minus(steps.get("eigs"), steps.get("3dgs"))
    add(
        "sharp view: one render, no event loss",
        "a view EDI marks sharp trains like `3dgs` (1 render) instead of N + 1 renders with the event loss",
        None if one is None else one / 1e3 * n_steps,
        f" per {n_steps} steps on such views ({fmt(one)} ms a step)",
        "none: the N + 1 renders of a still view coincide",
        "train-step-methods.json",
    )
    up = facts.get("train_jobs", 0) - facts.get("upstream_jobs", 0)
    per = None if edi_s is None or colmap_s is None else edi_s + colmap_s
    add(
        "upstream artifacts once per scene and B",
        f"{facts.get('upstream_jobs', '?')} EDI/SfM/init jobs for "
        f"{facts.get('train_jobs', '?')} training jobs ({up} fewer of each)",
        None if per is None else per * up,
        " for this config",
        "none (the same files)",
        "edi.json, sfm.json, config",
    )
    runs = facts.get("table_runs", {})
    cells = sum(r["rows"] for r in runs.values())
    twice = {name: r for name, r in runs.items() if r["rows"] > 1}
    missing = [r["method"] for r in twice.values() if r["method"] not in steps]
    retrain = (
        None
        if missing or not twice
        else sum((r["rows"] - 1) * steps[r["method"]] / 1e3 * (r["steps"] or n_steps) for r in twice.values())
    )
    shared = ", ".join(f"`{name}` in {r['rows']}" for name, r in twice.items()) or "none shared"
    add(
        "a run in several tables trains once",
        f"{cells} table rows name {len(runs)} runs: {cells - len(runs)} trainings fewer per scene ({shared})",
        retrain,
        " per scene (step time × the run's steps)",
        "none (one run folder)",
        "train-step-methods.json, eigs.tables.rows",
    )
    add(
        "synthetic scenes: no BRISQUE",
        "ground truth exists: PSNR/SSIM/LPIPS only",
        None if brisque_ms is None else brisque_ms / 1e3,
        " per image",
        "none (BRISQUE is the no-reference fallback)",
        "metrics.json",
    )
    add(
        "real scenes: no reference metrics",
        "no ground truth: BRISQUE on training views and a render path instead",
        None,
        "n/a (nothing to compare with)",
        "reference metrics are undefined without ground truth",
        "",
    )
    add("a config change reruns only what it touches", "a training option: `train`/`evaluate` of that run only "
        "(params trigger; tests/test_workflow_skips.py)", None if None in (synth_s, edi_s, colmap_s)
        else synth_s + edi_s + colmap_s, " per scene (synth + EDI + SfM)", "none (the same files)",
        "synth.json, edi.json, sfm.json")  # fmt: skip
    bar_figure(fig, [w for w, _ in saved], [v for _, v in saved], [f" {v:.3g} s" for _, v in saved],
               "time saved (s, unit in the table)", (7, 0.45 * max(len(saved), 1) + 1), log_x=True)
    return (
        "## What a scene does not need (skips)\n\nEach skip, the time it saves (from this run's measurements) and "
        "what it changes in quality. The dry-run side (jobs not scheduled) is tested in "
        "`tests/test_workflow_skips.py`.\n\n"
        f"![skips](figures/{fig.name})\n\n" + table(["skip", "how", "time saved", "quality", "source"], rows)
    )


def header(quick: bool, d: Path) -> str:
    docs = [json.loads(p.read_text()) for p in sorted(d.glob("*.json"))]
    dates = sorted({x.get("date", "") for x in docs} - {""})
    loads = [x["load_average"][0] for x in docs if x.get("load_average")]
    load = f"; 1-minute load average {min(loads):.1f}–{max(loads):.1f} as the sections finished" if loads else ""
    mode = ("quick mode (`--config bench_quick=1`: few scenes, sizes and repeats; a first look, not the reference "
            "numbers)") if quick else "full mode"  # fmt: skip
    return (
        "# Benchmarks\n\n"
        "Generated by `snakemake --cores N bench` (rules/bench.smk: the scripts in `bench/` as jobs writing "
        "`results/bench/`, then `bench/report.py`); never run by CI. Each section names the machine and the date it "
        "was measured; compare ratios measured in one run, since absolute times on shared machines drift. "
        f"This file: {mode}, measured {', '.join(dates) or 'n/a'} on {os.cpu_count()} cores{load}.\n"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="the bench outputs (NAME.md, NAME.json)")
    ap.add_argument("-o", "--output", type=Path, required=True, help="the Markdown report to write")
    ap.add_argument("--figures", type=Path, required=True, help="folder of the figures (bench_<name>.png)")
    ap.add_argument("--quick", action="store_true", help="the run was in quick mode (said in the header)")
    ap.add_argument("--facts", default="{}", help="JSON: job counts of the config (rules/bench.smk bench_facts)")
    args = ap.parse_args()
    facts = json.loads(args.facts)
    args.figures.mkdir(parents=True, exist_ok=True)
    fig = {n: args.figures / f"bench_{n}.png" for n in FIGURES}
    rel = os.path.relpath(args.figures, args.output.parent)
    parts = [
        edi_overview(load(args.dir, "edi"), fig["edi"]),
        sfm_overview(load(args.dir, "sfm"), fig["sfm"]),
        rasterizer_overview(load(args.dir, "rasterizer"), fig["rasterizer"]),
        train_overview(load(args.dir, "train-step-methods"), fig["train"]),
    ]
    text = header(args.quick, args.dir)
    text += "\n## Time against error (overview)\n\n" + "\n\n".join(p for p in parts if p) + "\n\n"
    text += skips(args.dir, facts, fig["skips"]) + "\n"
    for name in SECTIONS:
        p = args.dir / f"{name}.md"
        if p.exists():
            text += "\n" + p.read_text().strip() + "\n"
    if rel != "figures":
        text = text.replace("](figures/", f"]({rel}/")
    args.output.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.output.with_name(args.output.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, args.output)
    print(f"wrote {args.output} and {len(fig)} figures in {args.figures}")


if __name__ == "__main__":
    main()
