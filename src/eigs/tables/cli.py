"""``eigs tables``: the paper's Tables I–V (CSV, Markdown, LaTeX) from evaluated runs."""

from __future__ import annotations

import argparse

HELP = "Tables I-V (CSV, Markdown, LaTeX) from metrics.json files, the paper's values beside ours"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.epilog = (
        "TABLES maps tables (table1 … table5) to their rows: row key → run name, e.g. "
        '\'{"table1": {"3dgs": "3dgs", "eigs": "eigs", "oracle": "oracle"}}\'; a table given replaces its default '
        "mapping (eigs.tables.rows). Row keys are the paper's (eigs.tables.paper); other keys add rows; the key "
        "`oracle` is the upper bound. Writes "
        "table{1..5}.{csv,md,tex}, tables.md (all tables) and per_scene.csv into OUTPUT, and brisque_rank.{csv,md} "
        "(BRISQUE's rank agreement with PSNR) where a scene was evaluated with --hidden-ground-truth."
    )
    p.add_argument("metrics", nargs="+", help="metrics.json files (eigs evaluate), one per run and scene")
    p.add_argument("--tables", default="{}", metavar="JSON", help="table → {row key: run name} as JSON "
                   "(default: eigs.tables.rows)")  # fmt: skip
    p.add_argument("-o", "--output", required=True, help="output directory (results/tables)")


def per_scene_csv(runs: dict) -> str:
    """One row per (run, scene) with every metric of the run's metrics.json."""
    import csv
    import io
    import math

    from eigs.tables.collect import REAL_COLUMNS, SYNTHETIC_COLUMNS

    cols = ["run", "method", "bins", "scene", *SYNTHETIC_COLUMNS, *REAL_COLUMNS, "train_seconds", "steps", "fps",
            "n_gaussians", "hidden_ground_truth", "run_dir"]  # fmt: skip
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for name in sorted(runs):
        s = runs[name]
        for scene in s.scenes:
            d = s.per_scene[scene]
            vals = [d["metrics"].get(g, {}).get(k) for g, k in {**SYNTHETIC_COLUMNS, **REAL_COLUMNS}.values()]
            row = [name, s.method, s.bins, scene, *vals, d.get("train_seconds"), d.get("steps"), d.get("fps"),
                   d.get("n_gaussians"), int(bool(d.get("hidden_ground_truth"))), d["run_dir"]]  # fmt: skip
            w.writerow(["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v for v in row])
    return buf.getvalue()


def run(args: argparse.Namespace) -> int:
    import json
    import logging
    from pathlib import Path

    from eigs.errors import EigsError
    from eigs.tables.agreement import agreement_rows, write_agreement
    from eigs.tables.agreement import to_markdown as agreement_md
    from eigs.tables.build import build_tables
    from eigs.tables.collect import summarise
    from eigs.tables.rows import table_rows
    from eigs.tables.write import to_markdown, write_table
    from eigs.util.atomic import atomic_path

    try:
        mappings = json.loads(args.tables)
    except ValueError as err:
        raise EigsError("--tables", f"not JSON ({err})") from None
    if not isinstance(mappings, dict) or not all(isinstance(m, dict) for m in mappings.values()):
        raise EigsError("--tables", "expected {table: {row key: run name}}")
    runs = summarise(args.metrics)
    tables = build_tables(table_rows(mappings), runs)
    out = Path(args.output)
    for t in tables:
        write_table(t, out)
    agreement = agreement_rows(runs)  # [] without a hidden-ground-truth scene
    if agreement:
        write_agreement(agreement, out)
    with atomic_path(out / "tables.md") as tmp:
        tmp.write_text("\n".join([*(to_markdown(t) for t in tables), *([agreement_md(agreement)] * bool(agreement))]))
    with atomic_path(out / "per_scene.csv") as tmp:
        tmp.write_text(per_scene_csv(runs))
    logging.getLogger("eigs.tables").info("wrote %d tables from %d runs (%d metrics files) to %s", len(tables),
                                          len(runs), len(args.metrics), out)  # fmt: skip
    return 0
