"""``eigs figures``: qualitative grids, time-versus-PSNR curves and the Pareto plot from evaluated runs."""

from __future__ import annotations

import argparse

HELP = "figures from metrics.json files: qualitative grid per scene, time-vs-PSNR curves, Pareto plot"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = (
        "Writes OUTPUT/qualitative_<scene>.png for every scene, OUTPUT/curves.png and OUTPUT/pareto.png. The grid "
        "shows the runs of --grid-runs (default: every run) in that order."
    )
    p.add_argument("metrics", nargs="+", help="metrics.json files (eigs evaluate), one per run and scene")
    p.add_argument("--grid-runs", default=None, metavar="A,B,…", help="runs shown in the qualitative grids")
    p.add_argument("-o", "--output", required=True, help="output directory (results/figures)")


def run(args: argparse.Namespace) -> int:
    import logging
    from pathlib import Path

    from eigs.artifacts import run as run_folder
    from eigs.tables.collect import read_metrics, summarise
    from eigs.tables.figures import pareto_plot, qualitative_grid, time_curves
    from eigs.util.atomic import atomic_path

    out = Path(args.output)
    runs = summarise(args.metrics)
    order = args.grid_runs.split(",") if args.grid_runs else sorted(runs)
    order = [r for r in order if r in runs] or sorted(runs)
    # grids named by the workflow's scene (the run folder's), which the workflow's figures rule expects; the scene
    # file's own name where a run folder is laid out otherwise
    found: dict[tuple[str, str], tuple[Path, dict]] = {}
    for p in args.metrics:
        d = read_metrics(p)
        found[(d["run"], run_folder.workflow_scene(d["run_dir"]) or d["scene"])] = (Path(p), d)
    scenes = sorted({s for _, s in found})
    for scene in scenes:
        entries = [(r, *found[(r, scene)]) for r in order if (r, scene) in found]
        if not entries:
            continue
        with atomic_path(out / f"qualitative_{scene}.png") as tmp:
            qualitative_grid(scene, entries, tmp)
    with atomic_path(out / "curves.png") as tmp:
        time_curves(runs, tmp)
    with atomic_path(out / "pareto.png") as tmp:
        pareto_plot(runs, tmp)
    logging.getLogger("eigs.figures").info("wrote figures of %d runs on %d scenes to %s", len(runs), len(scenes), out)
    return 0

