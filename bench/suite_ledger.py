"""Measure the default suite across work sessions: a ledger folder in git (default ``docs/suite``) that mirrors a
workflow directory's small outputs, so that each session runs the jobs still missing and saves what they measured.

The ledger holds, per job of the config's ``all`` DAG (``bench.schedule.jobs_of``) that finished in a workflow
directory: its Snakemake benchmark file (``benchmarks/<rule>/<name>.tsv``); for a training job the run folder's
``config.json`` and ``train_log.csv`` (never the model); for an evaluation job ``metrics.json``, ``per_image.csv``
and the one view the qualitative grid shows (``renders/<set>/<image>`` and its ground truth
``renders/gt_<set>/<image>``, chosen by ``eigs.tables.figures.grid_view``); and one provenance row in ``jobs.csv``
(job, benchmark, wall s, CPU s (the benchmark's ``cpu_time``: all threads, empty when Snakemake wrote NA), threads,
machine, commit, date (when the job finished: its benchmark file's time, UTC)). A job is in the ledger when its
benchmark file is there (written last) with its files.

``bench/suite_report.py --directory LEDGER`` and ``bench/schedule.py --directory LEDGER`` read it as a run;
``tables`` writes Tables I-V (``eigs tables``) to ``LEDGER/tables/`` and the time-versus-PSNR curves and the Pareto
plot to ``LEDGER/figures/``. The qualitative grids are not drawn: beside the renders kept here they read the blurry
input from the scene file (``results/<scene>/scene.h5``), which the ledger does not keep.

Run (docs/development.md, "Measuring the default suite across sessions"):
``.venv/bin/snakemake --cores 2 $(.venv/bin/python bench/suite_ledger.py missing)``, then
``.venv/bin/python bench/suite_ledger.py save --directory .``, commit the ledger;
``.venv/bin/python bench/suite_ledger.py missing --count``; ``.venv/bin/python bench/suite_ledger.py tables``.
Jobs retrained into a second ledger of the same config while the first held stale ones move over with ``merge
--source LEDGER2`` (then ``prune`` what is still stale).
"""

from __future__ import annotations

import argparse
import csv
import datetime as _dt
import fnmatch
import io
import json
import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench.schedule import LedgerError, jobs_of, merge_configs, read_benchmark  # noqa: E402
from eigs.artifacts import run as run_folder  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DEFAULT_LEDGER = REPO / "docs" / "suite"
JOBS_CSV = "jobs.csv"
JOBS_COLUMNS = ("job", "benchmark", "wall_s", "cpu_s", "threads", "machine", "commit", "date")
RUN_FILES = (run_folder.CONFIG, run_folder.LOG)  # a run folder's small files (the model is not kept)
EVAL_FILES = ("metrics.json", "per_image.csv")
MODEL_FILES = run_folder.MODEL_FILES  # one of them marks a finished run folder
MAX_RENDER_KB = 256


@dataclass(frozen=True)
class Job:
    """One job of the ``all`` DAG: ``id`` as in bench.schedule (``train:chair:eigs+``), ``bench`` its benchmark name
    (``train/chair_b4_eigs+``), ``rule`` the job id's first part; ``scene``, ``run``, ``bins`` for train/evaluate."""

    id: str
    bench: str
    threads: int
    rule: str
    scene: str = ""
    run: str = ""
    bins: int = 0

    @property
    def benchmark(self) -> str:
        return f"benchmarks/{self.bench}.tsv"

    @property
    def folder(self) -> str:
        """The run folder (train) or evaluation folder (evaluate), relative to a workflow directory."""
        if self.rule == "train":
            return f"results/{self.scene}/b{self.bins}/{self.run}"
        if self.rule == "evaluate":
            return f"results/{self.scene}/b{self.bins}/eval/{self.run}"
        return ""

    @property
    def files(self) -> list[str]:
        """The small output files the ledger keeps (besides the benchmark and the grid's renders)."""
        names = RUN_FILES if self.rule == "train" else EVAL_FILES if self.rule == "evaluate" else ()
        return [f"{self.folder}/{n}" for n in names]

    @property
    def target(self) -> str:
        """A Snakemake target that runs this job: the run's config.json (an output of rule train and of rule
        train_field alike) or the evaluation's metrics.json."""
        return self.files[0]


def load_config(path: Path | Sequence[Path]) -> dict:
    """A workflow config; several files are merged as Snakemake merges --configfile arguments (e.g. config/config.yaml
    config/ladder.yaml)."""
    paths = [path] if isinstance(path, (str, Path)) else list(path)
    docs = []
    for p in paths:
        try:
            docs.append(yaml.safe_load(Path(p).read_text()))
        except (OSError, yaml.YAMLError) as err:
            raise LedgerError(f"{p}: cannot read the config ({str(err).splitlines()[0]})") from None
        if not isinstance(docs[-1], dict):
            raise LedgerError(f"{p}: not a workflow config")
    cfg = merge_configs(docs)
    if not isinstance(cfg.get("scenes"), dict):
        raise LedgerError(f"{', '.join(map(str, paths))}: not a workflow config (no `scenes:`)")
    return cfg


def suite_jobs(cfg: dict) -> list[Job]:
    """Every job of ``cfg``'s ``all`` target, in bench.schedule.jobs_of's (stable) order."""
    out = []
    for jid, (name, _deps, threads) in jobs_of(cfg).items():
        rule = jid.split(":", 1)[0]
        if rule in ("train", "evaluate"):
            _, scene, run = jid.split(":", 2)
            # jobs_of names them <rule>/<scene>_b<B>_<run>: B as the schedule resolved it
            bins = int(name.split("/", 1)[1][len(scene) + 2 : -(len(run) + 1)])
            out.append(Job(jid, name, threads, rule, scene, run, bins))
        else:
            out.append(Job(jid, name, threads, rule))
    return out


def finished(directory: Path, job: Job) -> bool:
    """Whether ``job`` finished in the workflow directory: its benchmark file and (train, evaluate) its outputs."""
    d = Path(directory)
    if not (d / job.benchmark).is_file():
        return False
    if not all((d / f).is_file() for f in job.files):
        return False
    return job.rule != "train" or any((d / job.folder / m).is_file() for m in MODEL_FILES)


def outputs_without_benchmark(directory: Path, job: Job) -> bool:
    d = Path(directory)
    return bool(job.files) and not (d / job.benchmark).exists() and all((d / f).is_file() for f in job.files)


def in_ledger(ledger: Path, job: Job) -> bool:
    """A job is in the ledger when its benchmark file (written last) and its small files are."""
    return (ledger / job.benchmark).is_file() and all((ledger / f).is_file() for f in job.files)


def expected_train(cfg: dict, run: str) -> dict:
    """The ``train`` section of the config.json of a run trained with ``cfg``'s options for ``run``, as `eigs train`
    resolves them (TrainConfig's defaults; the method's own budget when the options set no ``steps``)."""
    from eigs.train.resolve import train_config

    spec = cfg["runs"][run]
    return train_config({"method": spec["method"], **spec.get("options", {})}).to_dict()


def option_changes(root: Path, cfg: dict, job: Job) -> str:
    """How the run behind a train or evaluate ``job`` in ``root`` (a ledger or a workflow directory) differs from
    ``cfg``'s options for it, e.g. ``steps 800 → 1200`` ("" when it does not, or when there is nothing to read)."""
    if job.rule not in ("train", "evaluate"):
        return ""
    want = expected_train(cfg, job.run)
    if job.rule == "evaluate":
        metrics = Path(root) / job.files[0]
        try:
            steps = json.loads(metrics.read_text()).get("steps")
        except (OSError, ValueError, AttributeError) as err:
            raise LedgerError(f"{metrics}: cannot read the evaluation ({err})") from None
        if steps is not None and steps != want["steps"]:
            return f"steps {steps} → {want['steps']}"
    run_config = Path(root) / "results" / job.scene / f"b{job.bins}" / job.run / "config.json"
    if not run_config.is_file():
        return ""
    try:
        have = json.loads(run_config.read_text())["train"]
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise LedgerError(f"{run_config}: cannot read the run's options ({err})") from None
    # a key the run's config.json lacks was added to TrainConfig after the run: the run had its default's behaviour
    from eigs.train.config import TrainConfig

    have = {**{k: v for k, v in TrainConfig().to_dict().items() if k not in have}, **have}
    keys = sorted(k for k in set(want) | set(have) if want.get(k) != have.get(k))
    return ", ".join(f"{k} {have.get(k)} → {want.get(k)}" for k in keys)


def stale_jobs(cfg: dict, ledger: Path) -> dict[str, str]:
    """Job id → change, for the train and evaluate jobs in the ledger whose run was trained with other options than
    ``cfg`` gives it now (a budget changed); `prune` removes them."""
    out = {}
    for job in suite_jobs(cfg):
        if in_ledger(Path(ledger), job):
            change = option_changes(ledger, cfg, job)
            if change:
                out[job.id] = change
    return out


def check_current(cfg: dict, ledger: Path) -> None:
    """Raise LedgerError when the ledger holds stale jobs (:func:`stale_jobs`): every command but `prune` reads the
    ledger as a run of the config."""
    stale = stale_jobs(cfg, ledger)
    if stale:
        first = next(iter(stale))
        raise LedgerError(f"{ledger}: {len(stale)} jobs were run with other options than the config ({first}: "
                          f"{stale[first]}): run `suite_ledger.py prune`, then the jobs `missing` lists")  # fmt: skip


def prune(cfg: dict, ledger: Path) -> list[str]:
    """Remove the stale jobs (:func:`stale_jobs`) from the ledger: their folder, benchmark file and jobs.csv row.
    Returns a line per job removed."""
    ledger = Path(ledger)
    stale = stale_jobs(cfg, ledger)
    jobs = {j.id: j for j in suite_jobs(cfg)}
    lines = []
    for jid, change in stale.items():
        job = jobs[jid]
        (ledger / job.benchmark).unlink()  # first: the job is out of the ledger even if the rest is interrupted
        shutil.rmtree(ledger / job.folder)
        lines.append(f"{jid}: removed ({change})")
    if stale:
        write_jobs_csv(ledger, [r for r in read_jobs_csv(ledger) if r.get("job") not in stale])
    return lines


def merge(cfg: dict, source: Path, ledger: Path) -> list[str]:
    """Move every job of ledger ``source`` (of the same config: runs retrained while ``ledger`` still held stale
    ones) into ``ledger``, in place of the job of the same id there: its folder, its benchmark file and its jobs.csv
    row, the provenance as ``source`` recorded it. Jobs of ``ledger`` that ``source`` lacks stay as they are; stale
    ones are then still stale (`prune` removes them). Refuses a ``source`` with stale or half-present jobs before it
    writes anything. Returns a line per job moved."""
    source, ledger = Path(source), Path(ledger)
    stale = stale_jobs(cfg, source)
    if stale:
        first = next(iter(stale))
        raise LedgerError(f"{source}: {len(stale)} jobs were run with other options than the config ({first}: "
                          f"{stale[first]})")  # fmt: skip
    jobs = {j.id: j for j in suite_jobs(cfg)}
    moves = []
    for row in read_jobs_csv(source):
        job = jobs.get(row.get("job", ""))
        if job is None:
            raise LedgerError(f"{source / JOBS_CSV}: {row.get('job')!r} is not a job of the config")
        if not in_ledger(source, job):
            raise LedgerError(f"{source}: {job.id} has a provenance row but not its files ({job.benchmark})")
        moves.append((job, row))
    rows = read_jobs_csv(ledger)
    lines = []
    for job, row in moves:
        if job.folder:
            shutil.rmtree(ledger / job.folder, ignore_errors=True)
            shutil.copytree(source / job.folder, ledger / job.folder)
        rows = [r for r in rows if r.get("job") != job.id] + [row]
        write_jobs_csv(ledger, rows)
        _copy(source / job.benchmark, ledger / job.benchmark)
        lines.append(f"{job.id}: moved ({row.get('commit', '')}, {row.get('date', '')})")
    return lines


def grid_renders(eval_dir: Path) -> list[str]:
    """The renders of an evaluation folder that the qualitative grid reads (relative to it): the view
    eigs.tables.figures.grid_view picks, rendered and (scenes with ground truth) its ground truth."""
    from eigs.errors import EigsError
    from eigs.tables.collect import read_metrics
    from eigs.tables.figures import grid_view

    try:
        kind, image, _view = grid_view(read_metrics(eval_dir / "metrics.json"), eval_dir)
    except (EigsError, OSError, KeyError, ValueError):
        return []
    return [f"renders/{k}/{image}" for k in (kind, f"gt_{kind}") if (eval_dir / "renders" / k / image).is_file()]


def _copy(src: Path, dst: Path) -> None:
    from eigs.util.atomic import atomic_path

    with atomic_path(dst) as tmp:
        shutil.copyfile(src, tmp)


def read_jobs_csv(ledger: Path) -> list[dict[str, str]]:
    p = ledger / JOBS_CSV
    if not p.exists():
        return []
    try:
        rows = list(csv.DictReader(p.open(newline="")))
    except (OSError, csv.Error) as err:
        raise LedgerError(f"{p}: cannot read the provenance table ({err})") from None
    if rows and "job" not in rows[0]:
        raise LedgerError(f"{p}: not a ledger provenance table (no `job` column)")
    return rows


def write_jobs_csv(ledger: Path, rows: list[dict[str, str]]) -> None:
    from eigs.util.atomic import atomic_path

    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=JOBS_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    with atomic_path(ledger / JOBS_CSV) as tmp:
        tmp.write_text(buf.getvalue())


def repo_commit() -> str:
    try:
        out = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return ""
    return out.stdout.strip()


def _machine() -> str:
    from bench._report import machine

    return machine()


def batch_machine(directory: Path) -> str | None:
    """The machine a bench/device_batch.py run measured on, from its ``batch.json`` in ``directory`` (None without
    one): the jobs of such a directory ran elsewhere, not on the machine that saves them."""
    path = directory / "batch.json"
    if not path.is_file():
        return None
    try:
        rep = json.loads(path.read_text())
        t = int(rep.get("threads_per_job", 1))  # reports written before run --threads: one thread
        jobs = "one-thread jobs" if t == 1 else f"jobs of {t} threads"
        return f"{rep['cpu']}, {int(rep['cores'])} cores, device_batch: {int(rep['workers'])} {jobs} at a time"
    except (ValueError, KeyError, TypeError) as err:
        raise LedgerError(f"{path}: not a device_batch report ({err})") from None


def save(
    directory: Path,
    cfg: dict,
    ledger: Path,
    *,
    commit: str | None = None,
    replace_present: bool = False,
    max_render_kb: float = MAX_RENDER_KB,
    machine: str | None = None,
    only: Sequence[str] = (),
) -> tuple[list[str], list[str]]:
    """Copy the jobs of ``cfg`` that finished in ``directory`` into ``ledger``. Returns (lines saved, lines skipped).
    ``only``: job-id glob patterns (``sfm:blocks:6``, ``*:tree:eigs-b8``); when given, the other jobs are left alone
    (a rerun of a few jobs in a directory whose other jobs came from another checkout).

    Every benchmark and metrics file to be copied is checked first, so a malformed one stops the command before it
    writes anything. Per job: its small files, then its jobs.csv row, then its benchmark file (so an interrupted
    save leaves the job missing, not half there)."""
    from eigs.errors import EigsError
    from eigs.tables.collect import read_metrics

    directory, ledger = Path(directory), Path(ledger)
    if not directory.is_dir():
        raise LedgerError(f"{directory}: no such workflow directory")
    todo: list[tuple[Job, float, float | None]] = []
    skipped: list[str] = []
    for job in suite_jobs(cfg):
        if only and not any(fnmatch.fnmatchcase(job.id, pat) for pat in only):
            continue
        present = in_ledger(ledger, job)
        if present and not replace_present:
            if finished(directory, job):
                skipped.append(f"{job.id}: in the ledger already (--replace to take this run's)")
            continue
        if not finished(directory, job):
            if outputs_without_benchmark(directory, job):
                skipped.append(f"{job.id}: outputs but no benchmark file {directory / job.benchmark}")
            continue
        change = option_changes(directory, cfg, job)
        if change:
            skipped.append(f"{job.id}: trained with other options than the config ({change})")
            continue
        wall, cpu = read_benchmark(directory / job.benchmark)
        if job.rule == "evaluate":
            try:
                read_metrics(directory / job.files[0])
            except EigsError as err:
                raise LedgerError(str(err)) from None
        todo.append((job, wall, cpu))
    if not todo:
        return [], skipped
    machine = (batch_machine(directory) or _machine()) if machine is None else machine
    commit = commit if commit is not None else repo_commit()
    rows = read_jobs_csv(ledger)
    saved: list[str] = []
    for job, wall, cpu in todo:
        files = list(job.files)
        if job.rule == "evaluate":
            if replace_present and (ledger / job.folder / "renders").exists():
                shutil.rmtree(ledger / job.folder / "renders")
            for r in grid_renders(directory / job.folder):
                kb = (directory / job.folder / r).stat().st_size / 1024
                if kb <= max_render_kb:
                    files.append(f"{job.folder}/{r}")
                else:
                    skipped.append(f"{job.id}: render {r} not kept ({kb:.0f} KB > {max_render_kb:g} KB)")
        for f in files:
            _copy(directory / f, ledger / f)
        finished_at = _dt.datetime.fromtimestamp((directory / job.benchmark).stat().st_mtime, _dt.UTC)
        rows = [r for r in rows if r.get("job") != job.id]
        rows.append({"job": job.id, "benchmark": job.bench, "wall_s": f"{wall:.2f}",
                     "cpu_s": "" if cpu is None else f"{cpu:.2f}", "threads": str(job.threads), "machine": machine,
                     "commit": commit, "date": finished_at.strftime("%Y-%m-%dT%H:%M:%SZ")})  # fmt: skip
        write_jobs_csv(ledger, rows)
        _copy(directory / job.benchmark, ledger / job.benchmark)
        cpu_text = "CPU NA" if cpu is None else f"{cpu:.0f} s CPU"
        saved.append(f"{job.id}: {wall:.0f} s wall, {cpu_text}, {len(files) + 1} file{'s' if files else ''}")
    return saved, skipped


def missing_jobs(cfg: dict, ledger: Path, rule: str | None = None) -> list[Job]:
    """The train and evaluate jobs (only ``rule``'s, when given) not in the ledger, in jobs_of's order."""
    rules = (rule,) if rule else ("train", "evaluate")
    return [j for j in suite_jobs(cfg) if j.rule in rules and not in_ledger(Path(ledger), j)]


def counts(cfg: dict, ledger: Path) -> dict[str, tuple[int, int]]:
    """Rule → (jobs in the ledger, jobs missing), train and evaluate first, then the other rules."""
    out: dict[str, list[int]] = {"train": [0, 0], "evaluate": [0, 0]}
    for j in suite_jobs(cfg):
        c = out.setdefault(j.rule, [0, 0])
        c[0 if in_ledger(Path(ledger), j) else 1] += 1
    return {k: (v[0], v[1]) for k, v in out.items()}


def tables(cfg: dict, ledger: Path) -> list[str]:
    """Tables I-V of the ledger's evaluated runs (``eigs tables``, the workflow's row mapping) into LEDGER/tables/,
    and the time-versus-PSNR curves and the Pareto plot (eigs.tables.figures) into LEDGER/figures/. Returns lines
    saying what was written."""
    from eigs.cli import main as eigs_main
    from eigs.errors import EigsError
    from eigs.tables.agreement import hidden_truth_scenes
    from eigs.tables.collect import summarise
    from eigs.tables.figures import pareto_plot, time_curves
    from eigs.tables.rows import configured_rows
    from eigs.util.atomic import atomic_path

    ledger = Path(ledger)
    evals = [j for j in suite_jobs(cfg) if j.rule == "evaluate" and in_ledger(ledger, j)]
    if not evals:
        raise LedgerError(f"{ledger}: no evaluated run in the ledger (run `save` after a session's jobs)")
    metrics = [str(ledger / j.files[0]) for j in evals]
    mapping = json.dumps(configured_rows(cfg.get("tables"), cfg.get("runs", {}) or {}), separators=(",", ":"))
    code = eigs_main(["tables", *metrics, "--tables", mapping, "-o", str(ledger / "tables")])
    if code:
        raise LedgerError(f"{ledger}: eigs tables failed (exit {code}; its error is above)")
    lines = [f"{ledger / 'tables'}: Tables I-V from {len(metrics)} metrics files"]
    try:
        runs = summarise(metrics)
    except EigsError as err:
        raise LedgerError(str(err)) from None
    if hidden_truth_scenes(runs):
        lines.append(f"{ledger / 'tables' / 'brisque_rank.md'}: BRISQUE's rank agreement with PSNR")
    # the metrics' run_dir is relative to the workflow directory: here, to the ledger
    for s in runs.values():
        for d in s.per_scene.values():
            if not Path(d["run_dir"]).is_absolute():
                d["run_dir"] = str(ledger / d["run_dir"])
    logged = {}
    for name, s in runs.items():  # curves of the runs whose train_log.csv is in the ledger
        per = {k: d for k, d in s.per_scene.items() if (Path(d["run_dir"]) / "train_log.csv").is_file()}
        if per:
            logged[name] = replace(s, per_scene=per, scenes=sorted(per))
    figures = ledger / "figures"
    with atomic_path(figures / "curves.png") as tmp:
        time_curves(logged, tmp)
    with atomic_path(figures / "pareto.png") as tmp:
        pareto_plot(runs, tmp)
    n_logs = sum(len(s.scenes) for s in logged.values())
    lines.append(f"{figures}: curves.png ({n_logs} training logs), pareto.png; no qualitative grids (they read "
                 "the blurry input from results/<scene>/scene.h5, which the ledger does not keep)")  # fmt: skip
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("--config", type=Path, nargs="+", default=[REPO / "config" / "config.yaml"],
                       help="config file(s), merged as Snakemake merges them (default config/config.yaml)")
        p.add_argument("--ledger", type=Path, default=DEFAULT_LEDGER, help="the ledger folder (default docs/suite)")

    p = sub.add_parser("save", help="copy the jobs that finished in a workflow directory into the ledger")
    p.add_argument("--directory", type=Path, required=True, help="the workflow directory of the session's run")
    common(p)
    p.add_argument("--commit", default=None, help="git commit of DIR's checkout (default: this repository's HEAD)")
    p.add_argument("--replace", action="store_true", help="overwrite jobs that are in the ledger already")
    p.add_argument("--only", action="append", default=[], metavar="GLOB",
                   help="save only the jobs whose id matches a glob ('*:tree:eigs-b8'); repeatable")  # fmt: skip
    p.add_argument("--max-render-kb", type=float, default=MAX_RENDER_KB,
                   help=f"keep the qualitative grid's renders up to this size (default {MAX_RENDER_KB} KB "
                   "each)")  # fmt: skip
    p = sub.add_parser("missing", help="the Snakemake targets of the train/evaluate jobs not in the ledger")
    common(p)
    p.add_argument("--rule", choices=("train", "evaluate"), default=None)
    p.add_argument("--count", action="store_true", help="jobs in the ledger and missing, per rule, instead")
    p = sub.add_parser("tables", help="Tables I-V (LEDGER/tables/) and the curves and Pareto plot (LEDGER/figures/)")
    common(p)
    p = sub.add_parser("prune", help="remove the jobs run with other options than the config (a budget changed)")
    common(p)
    p = sub.add_parser("merge", help="move the jobs of another ledger of the config into this one (replacing)")
    common(p)
    p.add_argument("--source", type=Path, required=True, help="the ledger whose jobs move (e.g. docs/suite_next)")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config)
        if args.command not in ("prune", "merge"):
            check_current(cfg, args.ledger)
        if args.command == "save":
            saved, skipped = save(args.directory, cfg, args.ledger, commit=args.commit, replace_present=args.replace,
                                  max_render_kb=args.max_render_kb, only=args.only)  # fmt: skip
            for line in saved:
                print(f"saved {line}")
            for line in skipped:
                print(f"skipped {line}")
            print(f"{args.ledger}: saved {len(saved)} jobs, skipped {len(skipped)}")
        elif args.command == "missing":
            if args.count:
                for rule, (done, miss) in counts(cfg, args.ledger).items():
                    if args.rule is None or rule == args.rule:
                        print(f"{rule}: {done} done, {miss} missing")
            else:
                targets = [job.target for job in missing_jobs(cfg, args.ledger, args.rule)]
                try:
                    sys.stdout.write("".join(f"{t}\n" for t in targets))
                    sys.stdout.flush()
                except BrokenPipeError:  # `missing | head -n N`: the rest is not wanted
                    os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        elif args.command == "prune":
            lines = prune(cfg, args.ledger)
            for line in lines:
                print(line)
            print(f"{args.ledger}: removed {len(lines)} jobs")
        elif args.command == "merge":
            lines = merge(cfg, args.source, args.ledger)
            for line in lines:
                print(line)
            print(f"{args.ledger}: moved {len(lines)} jobs from {args.source}")
        else:
            for line in tables(cfg, args.ledger):
                print(line)
    except LedgerError as err:
        print(f"suite_ledger.py {args.command}: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
