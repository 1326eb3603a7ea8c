"""One line per job of a workflow directory, read from its ``logs/`` while Snakemake runs (``eigs status``).

Every rule writes its command's output to ``logs/<stage>/<name>.log`` and, once the job succeeded, Snakemake
writes ``benchmarks/<stage>/<name>.tsv``. A job is *done* when its benchmark file is at least as new as its log,
*failed* when its log holds the CLI's one-line error or a Python traceback, else *running* (a job of a Snakemake
that was killed stays *running*; the age of its last line grows). What a line shows is read from the log text:
the last progress bar (``eigs.util.progress``: ``step n/N``), the last held-out PSNR a training run logged, the
phase an SfM job is in, or else the last log message.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

# a tqdm bar of eigs.util.progress in a log (non-interactive: one bar per carriage return)
BAR = re.compile(r"(?P<desc>[^\r\n|]*?):\s+\d+%\|[^|\r\n]*\|\s*(?P<n>\d+)/(?P<total>\d+) \[")
# a logging record of eigs.cli's format; it may follow a bar on the same line
RECORD = re.compile(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} (?P<level>[A-Z]+) (?P<logger>[\w.]+): (?P<msg>[^\r\n]*)")
EVAL = re.compile(r"^step (?P<step>\d+) .*PSNR (?P<set>novel|blur) (?P<psnr>\S+) dB")
WROTE_PSNR = re.compile(r"held-out PSNR (?P<set>novel|blur) (?P<psnr>\S+) dB")
RESUMED = re.compile(r"^resumed from .* at step (?P<step>\d+)")
PHASE = re.compile(r"^(?P<phase>[\w ]+) …$")  # eigs.sfm.run: one line as each phase starts
# the CLI's one-line error (or interruption), or the last line of a Python traceback
ERROR = re.compile(r"^(?:eigs \S+: (?:error: .*|interrupted)|\w*(?:Error|Exception|Interrupt)\b.*)$", re.MULTILINE)
NAME = re.compile(r"^(?P<scene>.+?)_b(?P<bins>\d+)(?:_(?P<run>.+))?$")


@dataclass(frozen=True)
class Job:
    stage: str  # logs/ subfolder (train, sfm, …) or the log's name for top-level logs (tables, resources)
    name: str  # "scene bB run" from the log's name
    state: str  # running, done or failed
    progress: str  # what the log says about how far it got
    age_s: float  # seconds since the log was last written


def _short(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


def _psnr(text: str) -> str:
    try:
        return f"{float(text):.2f}"
    except ValueError:
        return text


def describe_log(stage: str, text: str, done: bool) -> tuple[str, str]:
    """(state, progress) of a job from its log text; ``done``: Snakemake wrote its benchmark after the log."""
    bars = list(BAR.finditer(text))
    records = list(RECORD.finditer(text))
    errors = [] if done else [e.group(0) for e in ERROR.finditer(text)]
    if errors or (not done and "Traceback (most recent call last)" in text):
        return "failed", errors[-1].strip() if errors else "Traceback"
    state = "done" if done else "running"
    msgs = [r["msg"] for r in records]
    if stage == "train":
        return state, _train_progress(bars, msgs)
    if stage == "sfm" and not done:
        phases = [m["phase"] for m in map(PHASE.match, msgs) if m]
        if phases:
            return state, f"phase {phases[-1]}"
    if not done and bars and (not records or bars[-1].start() > records[-1].start()):
        b = bars[-1]
        return state, f"{b['desc'].strip()} {b['n']}/{b['total']}"
    return state, msgs[-1] if msgs else ""


def _train_progress(bars: list[re.Match[str]], msgs: list[str]) -> str:
    """``step n/N`` (a resumed run's bar counts from the step it resumed at: that step is added) and the last
    held-out PSNR (the final one once the run wrote its folder)."""
    offset = 0
    for m in msgs:
        if r := RESUMED.match(m):
            offset = int(r["step"])
    evals = [e for e in map(EVAL.match, msgs) if e]
    parts = []
    if bars:  # the bar prints at most every 5 s: a held-out PSNR logged since is the later step
        n = max(int(bars[-1]["n"]) + offset, int(evals[-1]["step"]) if evals else 0)
        total = int(bars[-1]["total"]) + offset
        parts.append(f"step {n}/{total} ({100 * n // total}%)")
    wrote = [w for w in map(WROTE_PSNR.search, msgs) if w]
    if wrote:
        parts.append(f"held-out PSNR {wrote[-1]['set']} {_psnr(wrote[-1]['psnr'])} dB (final)")
    elif evals:
        e = evals[-1]
        parts.append(f"held-out PSNR {e['set']} {_psnr(e['psnr'])} dB (step {e['step']})")
    return ", ".join(parts) if parts else (msgs[-1] if msgs else "")


def job_name(stem: str) -> str:
    m = NAME.match(stem)
    return " ".join(x for x in (m["scene"], f"b{m['bins']}", m["run"]) if x) if m else stem


def read_jobs(directory: Path, now: float | None = None) -> list[Job]:
    """Every job with a log under ``directory/logs``, oldest last write first."""
    now = time.time() if now is None else now
    logs = directory / "logs"
    jobs = []
    for path in logs.rglob("*.log") if logs.is_dir() else ():
        rel = path.relative_to(logs)
        try:
            mtime = path.stat().st_mtime
            text = path.read_text(errors="replace")
        except OSError:
            continue  # removed while we read
        bench = directory / "benchmarks" / rel.with_suffix(".tsv")
        done = bench.is_file() and bench.stat().st_mtime >= mtime
        stage = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        name = job_name(rel.stem) if len(rel.parts) > 1 else ""
        state, what = describe_log(stage, text, done)
        jobs.append((mtime, Job(stage, name, state, what, max(0.0, now - mtime))))
    return [job for _, job in sorted(jobs, key=lambda mj: mj[0])]


def format_age(seconds: float) -> str:
    s = int(seconds)
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    if s < 86400:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 86400}d{s % 86400 // 3600:02d}h"


def select(jobs: list[Job], recent: int) -> list[Job]:
    """Running and failed jobs, and the ``recent`` most recently finished ones (order kept)."""
    done = [i for i, j in enumerate(jobs) if j.state == "done"]
    keep = set(done[-recent:]) if recent > 0 else set()
    return [j for i, j in enumerate(jobs) if j.state != "done" or i in keep]


def format_status(jobs: list[Job], shown: list[Job], width: int = 120) -> str:
    """A count line, then one aligned line per shown job (stage, job, state, age of its last line, progress), each
    cut to ``width`` characters."""
    counts = {s: sum(j.state == s for j in jobs) for s in ("running", "failed", "done")}
    lines = [f"{len(jobs)} jobs in logs/: " + ", ".join(f"{n} {s}" for s, n in counts.items())]
    rows = [(j.stage, j.name, j.state, format_age(j.age_s) + " ago", j.progress) for j in shown]
    if rows:
        widths = [max(len(r[i]) for r in rows) for i in range(4)]
        for r in rows:
            cells = [r[0].ljust(widths[0]), r[1].ljust(widths[1]), r[2].ljust(widths[2]), r[3].rjust(widths[3]), r[4]]
            lines.append(_short("  ".join(cells).rstrip(), width))
    return "\n".join(lines)
