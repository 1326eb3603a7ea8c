"""Report a run of the workflow's `all` target (a finished one, or one under way): the time of every stage and of
every method, the schedule on 1, 2 and 8 cores simulated from the per-job times (bench/schedule.py), whether each
training run ended within 0.3 dB of the best held-out PSNR it reached, and the tables. Writes docs/suite.md.

Per-job times are Snakemake's benchmark files (``DIR/benchmarks/<rule>/<name>.tsv``): ``wall s`` as measured and
``CPU s`` (CPU seconds per thread: what the job takes alone, when other work shared the cores during the run; the wall
time for a job that ended before Snakemake's first sample, NA). DIR may be the ledger of bench/suite_ledger.py
(``docs/suite``: the jobs of several sessions), whose tables are in ``DIR/tables/``.

Run: ``.venv/bin/python bench/suite_report.py --directory DIR [--config config/config.yaml] [--out docs/suite.md]``
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections import defaultdict
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench._report import machine, table  # noqa: E402
from bench.plateau_reference import reference_dir  # noqa: E402
from bench.schedule import (  # noqa: E402
    LedgerError,
    job_time,
    jobs_of,
    load_speedups,
    simulate,
    sped_up,
    unscaled_jobs,
)
from eigs.util.atomic import atomic_path  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
TOLERANCE_DB = 0.3
RUN_COLUMNS = ["run", "method", "steps", "scenes", "CPU s", "wall s", "PSNR", "past best",
               f"within {TOLERANCE_DB} dB of best"]  # fmt: skip
# jobs a ledger cannot measure: they read every run's outputs, which no session of the ledger holds at once
UNMEASURED_RULES = ("tables", "figures", "video")  # jobs that read many runs at once; may be missing: 0 s


def read_curve(path: Path) -> list[tuple[int, float]]:
    """(step, held-out novel-view PSNR) of a train_log.csv ([] when absent)."""
    if not path.exists():
        return []
    return [(int(r["step"]), float(r["psnr_novel"])) for r in csv.DictReader(path.open()) if r.get("psnr_novel")]


def curve(directory: Path, scene: str, bins: int, run: str) -> list[tuple[int, float]]:
    """(step, held-out novel-view PSNR) of a finished run of the suite ([] when absent)."""
    return read_curve(directory / "results" / scene / f"b{bins}" / run / "train_log.csv")


def trained_steps(directory: Path, scene: str, bins: int, run: str) -> int:
    """The step count a finished run of the suite trained (its config.json)."""
    p = directory / "results" / scene / f"b{bins}" / run / "config.json"
    try:
        return int(json.loads(p.read_text())["train"]["steps"])
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise SystemExit(f"suite_report.py: error: {p}: cannot read the run's steps ({err})") from None


def reference_curve(directory: Path, scene: str, bins: int, run: str) -> list[tuple[int, float]]:
    """The held-out curve of the run's plateau reference (bench/plateau_reference.py: the run trained longer on the
    scene), [] when there is none."""
    return read_curve(reference_dir(directory, scene, bins, run) / "train_log.csv")


BEGIN, END = "<!-- suite-report:begin -->", "<!-- suite-report:end -->"


def splice(document: str, report: str, name: str = "README.md") -> str:
    """``document`` with the text between its BEGIN and END markers replaced by ``report`` (its title dropped, its
    sections one level down)."""
    i, j = document.find(BEGIN), document.find(END)
    if i < 0 or j < i:
        raise ValueError(f"{name}: no `{BEGIN}` … `{END}` block to write the report into")
    body = report.split("\n", 1)[1] if report.startswith("# ") else report
    body = "\n".join("#" + line if line.startswith("## ") else line for line in body.strip("\n").split("\n"))
    return document[: i + len(BEGIN)] + "\n\n" + body + "\n\n" + document[j:]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--directory", type=Path, required=True, help="the workflow directory of the run")
    ap.add_argument("--config", type=Path, default=REPO / "config" / "config.yaml")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "suite.md")
    ap.add_argument("--readme", type=Path, default=None,
                    help=f"also write the report into this file, between its {BEGIN} and {END} lines")  # fmt: skip
    ap.add_argument("--speedups", type=Path, default=None,
                    help="JSON {'factors': {run: now / then}} (bench/step_ab.py): adds the schedule with the training "
                         "times scaled by them")  # fmt: skip
    args = ap.parse_args()
    cfg = yaml.safe_load(args.config.read_text())
    try:
        factors = load_speedups(args.speedups) if args.speedups is not None else None
    except LedgerError as err:
        raise SystemExit(f"suite_report.py: error: {err}") from None
    jobs = jobs_of(cfg)
    try:
        times = {j: job_time(args.directory, jobs[j][0], jobs[j][2]) for j in jobs}
    except LedgerError as err:
        raise SystemExit(f"suite_report.py: error: {err}") from None
    done = {j: t for j, t in times.items() if t is not None}
    missing = sorted(j for j in jobs if j not in done)

    # time per stage (rule)
    by_rule: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for j, t in done.items():
        by_rule[jobs[j][0].split("/", 1)[0]].append(t)
    stage_rows = [[rule, len(ts), f"{sum(w for w, _ in ts) / 60:.1f}", f"{sum(c for _, c in ts) / 60:.1f}",
                   f"{sum(c for _, c in ts) / len(ts):.0f}"]
                  for rule, ts in sorted(by_rule.items(), key=lambda kv: -sum(c for _, c in kv[1]))]  # fmt: skip

    # time and plateau check per method
    bins_default = int(cfg.get("edi", {}).get("bins", [4])[0])
    per_run: dict[str, list[tuple[float, float, float, float]]] = defaultdict(list)
    run_steps: dict[str, set[int]] = defaultdict(set)
    ref_rows = []
    for j, t in sorted(done.items()):
        if not j.startswith("train:"):
            continue
        _, scene, run = j.split(":", 2)
        bins = int(cfg["runs"][run].get("bins", bins_default))
        c = curve(args.directory, scene, bins, run)
        if c:
            best = max(p for _, p in c)
            per_run[run].append((t[0], t[1], c[-1][1], best - c[-1][1]))
            run_steps[run].add(trained_steps(args.directory, scene, bins, run))
        ref = reference_curve(args.directory, scene, bins, run)
        if c and ref:
            ref_step, ref_best = max(ref, key=lambda sp: (sp[1], -sp[0]))
            short = ref_best - c[-1][1]
            verdict = "yes" if short <= TOLERANCE_DB else "**no**"
            ref_rows.append([run, scene, c[-1][0], f"{c[-1][1]:.2f}", ref[-1][0], f"{ref_best:.2f} ({ref_step})",
                             f"{ref[-1][1]:.2f}", f"{short:+.2f}", verdict])  # fmt: skip
    run_rows = []
    for run, vals in sorted(per_run.items(), key=lambda kv: -sum(v[1] for v in kv[1])):
        steps = sorted(run_steps[run])  # as trained (a field method's own default when the options set none)
        worst = max(v[3] for v in vals)
        run_rows.append([run, cfg["runs"][run]["method"], "/".join(map(str, steps)), len(vals),
                         f"{sum(v[1] for v in vals) / len(vals):.0f}", f"{sum(v[0] for v in vals) / len(vals):.0f}",
                         f"{sum(v[2] for v in vals) / len(vals):.2f}", f"{worst:.2f}",
                         "yes" if worst <= TOLERANCE_DB else "**no**"])  # fmt: skip

    md = [
        "# The default suite, measured\n",
        f"Written by `bench/suite_report.py` from the run in `{args.directory}` (config `{args.config.name}`); "
        f"{machine()}. {len(done)} of {len(jobs)} jobs have run"
        + (
            f"; not yet: {len(missing)} ({', '.join(missing[:6])}{', …' if len(missing) > 6 else ''})."
            if missing
            else "."
        ),  # fmt: skip
        "",
        "## Time per stage\n",
        "`CPU s` is CPU seconds per thread: the time a job takes when it has its cores to itself (the run shared the "
        "machine with other work, so its wall times are upper bounds).\n",
        table(["stage", "jobs", "wall min", "CPU min", "CPU s per job"], stage_rows),
        "",
        "## Training runs\n",
        f"Mean over the scenes run so far. `within {TOLERANCE_DB} dB of best`: the final held-out novel-view PSNR is "
        f"within {TOLERANCE_DB} dB of the best the run itself reached (`past best`: the largest shortfall over the "
        "scenes): a **no** is a run past its peak, not one stopped while still rising. Whether a run stopped before "
        "its plateau is read from longer runs: the plateau references below, and docs/results.md, section "
        "'Training budgets'.\n",
        table(RUN_COLUMNS, run_rows),
        "",
    ]
    if ref_rows:
        md += ["## Plateau references\n",
               "A run of the suite trained longer on one scene (bench/plateau_reference.py, same method and options, "
               "more steps; in the ledger's `plateau/`). `short`: the reference's best held-out PSNR minus the suite "
               f"run's final one; `within {TOLERANCE_DB} dB`: the suite run stopped within {TOLERANCE_DB} dB of the "
               "level its method reaches with more training.\n",
               table(["run", "scene", "steps", "final PSNR", "reference steps", "reference best (step)",
                      "reference final", "short", f"within {TOLERANCE_DB} dB"], ref_rows), ""]  # fmt: skip
    if all(j.split(":", 1)[0] in UNMEASURED_RULES for j in missing):
        cpu_times = {j: t[1] for j, t in done.items()} | {j: 0.0 for j in missing}
        sched = [[c, f"{simulate(jobs, cpu_times, c) / 3600:.2f}"] for c in (1, 2, 8)]
        cols = ["cores", "hours"]
        note = ""
        if factors is not None:
            current, since = unscaled_jobs(args.directory, args.speedups)
            scaled = sped_up(cpu_times, factors, current)
            for row, c in zip(sched, (1, 2, 8), strict=True):
                row.append(f"{simulate(jobs, scaled, c) / 3600:.2f}")
            cols.append("hours, today's step")
            shown = ", ".join(f"`{r}` {f:.2f}" for r, f in sorted(factors.items()))
            note = (f" `hours, today's step`: an estimate, every training job's recorded time multiplied by its run's "
                    f"step-time ratio today / when the ledger was trained, measured by bench/step_ab.py "
                    f"(`{args.speedups.name}`; runs not listed unchanged"
                    + (f", and the {len(current)} training jobs trained at or after `{since}`, the code the ratios' "
                       "\"today\" was measured with, or after the code their run's ratio was measured against, as "
                       "recorded" if current else "")
                    + f"): {shown}.")  # fmt: skip
        md += ["## Schedule\n", "`snakemake --cores N all` simulated from the per-job CPU times (bench/schedule.py: a "
               "job starts when its inputs exist and its threads are free, longest remaining path first)"
               + (f"; the {' and '.join(sorted({j.split(':', 1)[0] for j in missing}))} jobs not measured, counted as "
                  "0 s" if missing else "") + "." + note + "\n",
               table(cols, sched), ""]  # fmt: skip
    for tables in (args.directory / "results" / "tables" / "tables.md", args.directory / "tables" / "tables.md"):
        if tables.exists():
            md += ["## Tables\n", tables.read_text()]
            break
    report = "\n".join(md) + "\n"
    if args.readme is not None:
        try:
            spliced = splice(args.readme.read_text(), report, str(args.readme))
        except (OSError, ValueError) as err:
            raise SystemExit(f"suite_report.py: error: {err}") from None
        with atomic_path(args.readme) as tmp:
            tmp.write_text(spliced)
    with atomic_path(args.out) as tmp:
        tmp.write_text(report)
    print(f"wrote {args.out}: {len(done)} of {len(jobs)} jobs")


if __name__ == "__main__":
    main()
