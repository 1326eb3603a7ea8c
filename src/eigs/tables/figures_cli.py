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

    from eigs.tables.collect import read_metrics, summarise
    from eigs.tables.figures import pareto_plot, qualitative_grid, time_curves
    from eigs.util.atomic import atomic_path

    out = Path(args.output)
    runs = summarise(args.metrics)
    order = args.grid_runs.split(",") if args.grid_runs else sorted(runs)
    order = [r for r in order if r in runs] or sorted(runs)
    paths = {}
    for p in args.metrics:
        d = read_metrics(p)
        paths[(d["run"], d["scene"])] = Path(p)
    scenes = sorted({s for r in runs.values() for s in r.scenes})
    for scene in scenes:
        entries = [(r, paths[(r, scene)], runs[r].per_scene[scene]) for r in order if (r, scene) in paths]
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

