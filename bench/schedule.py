"""Simulate the workflow's schedule on N cores from per-job times: how long `snakemake --cores N all` takes when the
jobs are independent except for their inputs (synth → edi (edi_frames on `events: false` scenes) → sfm → init per
scene and B, the other B's sfm after the first's where it is resampled; train → evaluate per run on the scenes
eigs.plan gives it, the workflow's own run planning; tables and figures last). Jobs take their rule's threads
(config `threads`; init, resources, evaluate, tables and figures 1), a job starts as soon as its inputs exist and
enough cores are free, longest remaining path first.

Per-job seconds come from a finished run's Snakemake benchmark files (``DIR/benchmarks/<rule>/<name>.tsv``: the
wall-clock ``s`` column, or with ``--column cpu_time`` the CPU seconds divided by the job's threads, which is the
wall time the job would take alone when other work shared the cores while it ran) or, for jobs not run there, from
``--estimate RULE[:RUN]=SECONDS`` (e.g. ``train:eigs=318``); a job with neither is an error naming it.

Run: ``.venv/bin/python bench/schedule.py --config config/toy.yaml --directory /path/of/a/run --cores 1 2 8``"""

from __future__ import annotations

import argparse
import csv
import functools
import heapq
import io
import json
import math
import re
import subprocess
from pathlib import Path

import yaml

from eigs import plan


def merge_configs(docs: list[dict]) -> dict:
    """Config documents merged as Snakemake merges several --configfile arguments: later ones update earlier ones,
    dictionaries key by key (so config/ladder.yaml adds runs to config/config.yaml's)."""

    def update(a: dict, b: dict) -> dict:
        for k, v in b.items():
            a[k] = update(dict(a[k]), v) if isinstance(v, dict) and isinstance(a.get(k), dict) else v
        return a

    out: dict = {}
    for d in docs:
        out = update(out, d or {})
    return out


def jobs_of(cfg: dict) -> dict[str, tuple[str, list[str], int]]:
    """Job id → (benchmark name, dependencies, threads) for the `all` target of ``cfg``, scenes and runs in the
    config's order (which scenes, B and runs: eigs.plan, as rules/common.smk plans them)."""
    threads = int(cfg.get("threads", 2))
    scenes = cfg["scenes"]
    jobs: dict[str, tuple[str, list[str], int]] = {"resources": ("resources", [], 1)}
    for s, spec in scenes.items():
        builtin = "builtin" in spec
        jobs[f"scene:{s}"] = (f"synth/{s}" if builtin else f"ingest/{s}", [], threads if builtin else 1)
        for b in plan.edi_bins(cfg):
            if plan.scene_uses_events(cfg, s):
                jobs[f"edi:{s}:{b}"] = (f"edi/{s}_b{b}", [f"scene:{s}"], threads)
            else:  # rules/edi.smk edi_frames: the frames passed through, 1 thread
                jobs[f"edi:{s}:{b}"] = (f"edi_frames/{s}_b{b}", [f"scene:{s}"], 1)
            base = plan.sfm_base_bins(cfg, s, b)  # rule sfm_resample: the first B's SfM read at this B's times
            if base is None:
                jobs[f"sfm:{s}:{b}"] = (f"sfm/{s}_b{b}", [f"edi:{s}:{b}"], threads)
            else:
                jobs[f"sfm:{s}:{b}"] = (f"sfm/{s}_b{b}", [f"edi:{s}:{b}", f"sfm:{s}:{base}"], 1)
            jobs[f"init:{s}:{b}"] = (f"init/{s}_b{b}", [f"sfm:{s}:{b}"], 1)
    evals = []
    for r in plan.runs(cfg):
        b = plan.run_bins(cfg, r)
        trained = set(plan.run_scenes(cfg, r))
        for s in (s for s in scenes if s in trained):
            jobs[f"train:{s}:{r}"] = (f"train/{s}_b{b}_{r}", [f"init:{s}:{b}"], threads)
            jobs[f"evaluate:{s}:{r}"] = (f"evaluate/{s}_b{b}_{r}", [f"train:{s}:{r}", "resources"], 1)
            evals.append(f"evaluate:{s}:{r}")
    jobs["tables"] = ("tables", evals, 1)
    jobs["figures"] = ("figures", evals, 1)
    for s, deps in video_trainings(cfg, jobs).items():
        jobs[f"video:{s}"] = (f"video/{s}", deps, 1)
    return jobs


def video_trainings(cfg: dict, jobs: dict) -> dict[str, list[str]]:
    """Scene → the training jobs its orbit video renders (eigs.plan.video_runs), in the config's scene order."""
    shown = plan.video_runs(cfg)
    out: dict[str, list[str]] = {}
    for s in cfg["scenes"]:
        deps = [f"train:{s}:{r}" for r in shown if f"train:{s}:{r}" in jobs]
        if deps:
            out[s] = deps
    return out


class LedgerError(Exception):
    """A user-facing problem, printed on one line (``PATH: problem``) without a traceback."""


def read_benchmark(path: Path) -> tuple[float, float | None]:
    """(wall s, CPU s of all threads) of a Snakemake benchmark file (its last row); CPU None when Snakemake wrote NA
    (a job that ended before its first sample). A missing or malformed file is a LedgerError naming it."""
    try:
        text = Path(path).read_text()
    except OSError as err:
        raise LedgerError(f"{path}: cannot read the benchmark file ({err.strerror or err})") from None
    try:
        rows = list(csv.DictReader(io.StringIO(text), delimiter="\t"))
    except csv.Error as err:
        raise LedgerError(f"{path}: not a Snakemake benchmark file ({err})") from None
    if not rows:
        raise LedgerError(f"{path}: not a Snakemake benchmark file (no header and row)")
    row = rows[-1]
    if "s" not in row or "cpu_time" not in row:
        raise LedgerError(f"{path}: not a Snakemake benchmark file (no `s` and `cpu_time` columns)")
    try:
        wall = float(row["s"])
        cpu = None if (row["cpu_time"] or "").strip() == "NA" else float(row["cpu_time"])
    except (TypeError, ValueError):
        raise LedgerError(f"{path}: not a Snakemake benchmark file (s = {row['s']!r}, "
                          f"cpu_time = {row['cpu_time']!r})") from None  # fmt: skip
    if not math.isfinite(wall) or wall < 0 or (cpu is not None and (not math.isfinite(cpu) or cpu < 0)):
        raise LedgerError(f"{path}: benchmark times out of range (s = {row['s']}, cpu_time = {row['cpu_time']})")
    return wall, cpu


REPO = Path(__file__).resolve().parents[1]  # the repository whose history jobs.csv's commits are in
TRAIN_BENCHMARK = re.compile(r"^train/(?P<scene>.+)_b(?P<bins>\d+)_(?P<run>[^_/]+)$")


def process_cpu_seconds(directory: Path, name: str) -> float | None:
    """A training job's own CPU seconds (``run.process_cpu_s`` of its config.json, written by runs since 2026-11-26),
    or None (another rule, an older run, a missing or unreadable file). A run resumed from a checkpoint
    (``run.resumed_at_step`` > 0) recorded only its last process's CPU time, as did its benchmark file: its
    accumulated training seconds (``run.train_seconds``, the wall time of every process's steps) stand for it."""
    m = TRAIN_BENCHMARK.match(name)
    if m is None:
        return None
    p = Path(directory) / "results" / m["scene"] / f"b{m['bins']}" / m["run"] / "config.json"
    try:
        run = json.loads(p.read_text())["run"]
        resumed = run.get("resumed_at_step") or 0
        value = run["train_seconds"] if isinstance(resumed, int) and resumed > 0 else run["process_cpu_s"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return None
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) and value >= 0 else None


def job_time(directory: Path, name: str, threads: int) -> tuple[float, float] | None:
    """(wall s, CPU s per thread) of one job, or None when it has not run. CPU seconds: a training job's own
    (:func:`process_cpu_seconds`) where its run recorded them, else the benchmark file's (Snakemake samples CPU time
    every 30 s after a job's first 30 and misses up to that much of its end); an NA CPU time counts as the wall
    time; a malformed benchmark file is a LedgerError naming it."""
    p = Path(directory) / "benchmarks" / f"{name}.tsv"
    if not p.exists():
        return None
    wall, cpu = read_benchmark(p)
    own = process_cpu_seconds(directory, name)
    if own is not None:
        cpu = own
    return wall, (wall if cpu is None else cpu / max(threads, 1))


def seconds(
    directory: Path | None, name: str, estimates: dict[str, float], column: str = "s", threads: int = 1
) -> float:
    measured = job_time(directory, name, threads) if directory is not None else None
    if measured is not None:
        return measured[1] if column == "cpu_time" else measured[0]
    rule, _, rest = name.partition("/")
    run = rest.rsplit("_", 1)[-1] if rule in ("train", "evaluate") else ""
    for key in (f"{rule}:{run}", rule):
        if key in estimates:
            return estimates[key]
    raise SystemExit(f"no benchmark and no --estimate for job {name}")


def load_speedups(path: Path) -> dict[str, float]:
    """Per-run step-time factors (now / then, as bench/step_ab.py measures them) from a JSON file's ``factors``.

    Applied to a training job's recorded time they estimate it with today's code: an estimate, stated as one wherever
    it is printed (issue 46: "a measured per-method speed-up applied to their recorded times")."""
    try:
        doc = json.loads(Path(path).read_text())
        factors = {str(k): float(v) for k, v in doc["factors"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise LedgerError(f"{path}: not a speed-up file ({{'factors': {{run: now / then}}}}): {err}") from None
    bad = [k for k, v in factors.items() if not (math.isfinite(v) and v > 0)]
    if bad:
        raise LedgerError(f"{path}: factors must be finite and > 0: {', '.join(bad)}")
    return factors


def speedups_measured_at(path: Path) -> str | None:
    """The commit a speed-up file's "now" was measured at (its ``measured_at``), or None when it names none."""
    try:
        commit = json.loads(Path(path).read_text()).get("measured_at")
    except (OSError, ValueError, AttributeError):
        return None
    return str(commit) if commit else None


@functools.cache
def _ancestry(repo: Path, older: str, newer: str) -> int:
    """``git merge-base --is-ancestor older newer`` in ``repo``: 0 when ``older`` is ``newer`` (either a prefix of the
    other) or an ancestor of it, 1 when not, another code when git does not know one of them."""
    if older.startswith(newer) or newer.startswith(older):
        return 0
    return subprocess.run(["git", "-C", str(repo), "merge-base", "--is-ancestor", older, newer],
                          capture_output=True).returncode  # fmt: skip


def _training_rows(directory: Path) -> list[tuple[str, str]]:
    """(job, commit) of the training jobs of a ledger's ``jobs.csv`` that record a commit; empty without the file."""
    path = Path(directory) / "jobs.csv"
    if not path.exists():
        return []
    with path.open(newline="") as f:
        return [(r["job"], r["commit"]) for r in csv.DictReader(f)
                if r.get("job", "").startswith("train:") and r.get("commit")]  # fmt: skip


def jobs_trained_since(directory: Path, commit: str, repo: Path = REPO) -> set[str]:
    """Training jobs of a ledger's ``jobs.csv`` recorded at ``commit`` or at a commit after it (``git merge-base
    --is-ancestor`` in ``repo``): their times are already today's, and a speed-up factor measured at ``commit`` does
    not apply to them. Empty without a jobs.csv; a commit git does not know counts as older."""
    return {job for job, c in _training_rows(directory) if _ancestry(repo, commit, c) == 0}


def speedups_against(path: Path) -> dict[str, str]:
    """Run → the commit a speed-up file's ratio for it was measured against (its ``against``; empty when absent)."""
    try:
        doc = json.loads(Path(path).read_text()).get("against") or {}
    except (OSError, ValueError, AttributeError):
        return {}
    return {str(k): str(v) for k, v in doc.items()}


def jobs_past_their_factor(directory: Path, against: dict[str, str], repo: Path = REPO) -> set[str]:
    """Training jobs of a ledger's ``jobs.csv`` recorded after the commit their run's factor was measured against
    (their commit not ``against[run]`` or an ancestor of it): retrained since, they already carry part of the gain
    the factor measures, and are left as recorded (a conservative estimate). A commit git does not know counts as
    older, as in :func:`jobs_trained_since`."""

    def after(c: str, base: str) -> bool:
        code = _ancestry(repo, c, base)
        if code in (0, 1):
            return code == 1
        return _known(repo, c)  # git knows c but not ``base``: c counts as after it

    out = set()
    for job, c in _training_rows(directory):
        run = job.split(":", 2)[-1]
        if run in against and after(c, against[run]):
            out.add(job)
    return out


@functools.cache
def _known(repo: Path, commit: str) -> bool:
    """Whether git in ``repo`` knows ``commit``."""
    return subprocess.run(["git", "-C", str(repo), "cat-file", "-e", f"{commit}^{{commit}}"],
                          capture_output=True).returncode == 0  # fmt: skip


def unscaled_jobs(directory: Path | None, speedups: Path, repo: Path = REPO) -> tuple[set[str], str | None]:
    """The training jobs a speed-up file's factors do not scale (:func:`jobs_trained_since` its ``measured_at``, and
    :func:`jobs_past_their_factor`), and that ``measured_at``."""
    since = speedups_measured_at(speedups)
    if directory is None:
        return set(), since
    current = jobs_trained_since(directory, since, repo) if since else set()
    return current | jobs_past_their_factor(directory, speedups_against(speedups), repo), since


def sped_up(times: dict[str, float], factors: dict[str, float], current: set[str] | None = None) -> dict[str, float]:
    """``times`` with every training job of a run in ``factors`` scaled by its factor (keys ``train:SCENE:RUN``),
    except the jobs in ``current`` (those the factors do not apply to: :func:`unscaled_jobs`)."""
    out = dict(times)
    for j, t in times.items():
        rule, _, rest = j.partition(":")
        run = rest.split(":", 1)[-1]
        if rule == "train" and run in factors and j not in (current or set()):
            out[j] = t * factors[run]
    return out


def simulate(jobs: dict, times: dict[str, float], cores: int) -> float:
    """Makespan (s) of list scheduling, longest remaining path first."""
    succ: dict[str, list[str]] = {j: [] for j in jobs}
    for j, (_, deps, _) in jobs.items():
        for d in deps:
            succ[d].append(j)
    rank: dict[str, float] = {}

    def r(j: str) -> float:
        if j not in rank:
            rank[j] = times[j] + max((r(k) for k in succ[j]), default=0.0)
        return rank[j]

    waiting = {j: len(jobs[j][1]) for j in jobs}
    ready = [(-r(j), j) for j in jobs if waiting[j] == 0]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []
    free, now = cores, 0.0
    while ready or running:
        started = True
        while started:
            started = False
            for _, j in sorted(ready):
                need = min(jobs[j][2], cores)
                if need <= free:
                    ready.remove((-r(j), j))
                    heapq.heapify(ready)
                    free -= need
                    heapq.heappush(running, (now + times[j], j))
                    started = True
                    break
        now, j = heapq.heappop(running)
        free += min(jobs[j][2], cores)
        for k in succ[j]:
            waiting[k] -= 1
            if waiting[k] == 0:
                heapq.heappush(ready, (-r(k), k))
    return now


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", required=True)
    ap.add_argument("--directory", type=Path, default=None, help="workflow directory with a finished run's benchmarks/")
    ap.add_argument("--cores", type=int, nargs="+", default=[2, 8])
    ap.add_argument("--estimate", action="append", default=[], metavar="RULE[:RUN]=SECONDS")
    ap.add_argument("--speedups", type=Path, default=None,
                    help="JSON {'factors': {run: now / then}}: training times scaled by their factor")  # fmt: skip
    ap.add_argument(
        "--column",
        choices=("s", "cpu_time"),
        default="s",
        help="wall seconds, or CPU seconds per thread (for runs that shared the cores with other work)",
    )
    args = ap.parse_args()
    cfg = yaml.safe_load(Path(args.config).read_text())
    est = {k: float(v) for k, v in (e.split("=", 1) for e in args.estimate)}
    jobs = jobs_of(cfg)
    times = {j: seconds(args.directory, jobs[j][0], est, args.column, jobs[j][2]) for j in jobs}
    if args.speedups is not None:
        try:
            factors = load_speedups(args.speedups)
        except LedgerError as err:
            raise SystemExit(f"schedule.py: error: {err}") from None
        current, since = unscaled_jobs(args.directory, args.speedups)
        times = sped_up(times, factors, current)
        print(f"training times scaled by the step speed-ups of {args.speedups} (an estimate), except {len(current)} "
              f"training jobs trained at or after {since} or after the code their run's ratio was measured "
              "against")  # fmt: skip
    print(f"{len(jobs)} jobs, {sum(times.values()) / 3600:.2f} h of job time in total")
    for c in args.cores:
        print(f"--cores {c}: {simulate(jobs, times, c) / 3600:.2f} h")


if __name__ == "__main__":
    main()
