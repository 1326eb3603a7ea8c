"""Faults a user meets, applied to the real workflow: SIGKILL at chosen instants, and checks of what is left.

- :func:`run_workflow` starts ``snakemake all`` in its own process group and, given an :class:`Instant`, kills the
  whole group with SIGKILL ``delay_s`` after the first job of ``rule`` starts (as a user's Ctrl-\\, an OOM killer or
  a lost node would).
- :func:`recover` is what README.md and docs/development.md tell a user to do after a crash or a kill:
  ``snakemake --unlock`` with the same arguments, then the same command again (the workflow profile's
  ``rerun-incomplete`` redoes the jobs that were interrupted).
- :func:`marked_incomplete` reads Snakemake's own record of interrupted outputs (``.snakemake/incomplete``);
  :func:`check_results` opens every other file under ``results/`` with a reader of its type, so a partial file that
  looks complete — one a later job would read — is found.
"""

from __future__ import annotations

import base64
import csv
import json
import os
import queue
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from eigs.util.atomic import ANY_TEMPORARY

REPO = Path(__file__).resolve().parents[2]
SNAKEFILE = REPO / "workflow" / "Snakefile"
JOB_START = re.compile(r"^(?:local)?rule (\w+):\s*$")
JOB_END = re.compile(r"Finished jobid: \d+ \(Rule: (\w+)\)")
# columns measured in wall time: they differ between two uninterrupted runs as well
TIMING_COLUMNS = re.compile(r"^(time_s|fps|train_seconds|render_ms)(_|$)")


@dataclass(frozen=True)
class Instant:
    """Kill ``delay_s`` seconds after the first job of ``rule`` starts."""

    rule: str
    delay_s: float

    def __str__(self) -> str:
        return f"{self.rule}+{self.delay_s:.2f}s"


@dataclass
class Outcome:
    """One workflow start: killed (at which instant, with the jobs started so far) or ran to its end."""

    killed: bool
    returncode: int | None
    rules_started: list[str]
    running: list[str]  # the rules whose jobs were running when it was killed (or ended)
    output: str


def snakemake_args(workdir: Path, configfile: Path, cores: int = 2) -> list[str]:
    """The user's command, run in ``workdir`` (results/, logs/, .snakemake/ land there)."""
    return ["all", "--cores", str(cores), "-s", str(SNAKEFILE), "--directory", str(workdir),
            f"--configfile={configfile}"]  # fmt: skip


def _reader(stream, lines: queue.Queue) -> None:
    for line in iter(stream.readline, ""):
        lines.put(line)
    lines.put(None)


def run_workflow(workdir: Path, configfile: Path, instant: Instant | None = None, timeout_s: float = 900) -> Outcome:
    """``snakemake all``; with ``instant``, SIGKILL to its whole process group at that instant. Returns once every
    process of the group is gone."""
    env = {**os.environ, "EIGS_PROGRESS": "0"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "snakemake", *snakemake_args(workdir, configfile)],
        cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True, env=env,
    )  # fmt: skip
    lines: queue.Queue = queue.Queue()
    threading.Thread(target=_reader, args=(proc.stdout, lines), daemon=True).start()
    out: list[str] = []
    started: list[str] = []
    finished: list[str] = []
    kill_at: float | None = None
    deadline = time.monotonic() + timeout_s
    killed = False
    while True:
        now = time.monotonic()
        if kill_at is not None and now >= kill_at:
            _kill_group(proc)
            killed = True
            break
        if now > deadline:
            _kill_group(proc)
            raise TimeoutError(f"snakemake ran past {timeout_s} s:\n" + "".join(out[-40:]))
        wait = 0.05 if kill_at is None else max(0.0, min(0.05, kill_at - now))
        try:
            line = lines.get(timeout=wait)
        except queue.Empty:
            continue
        if line is None:
            break
        out.append(line)
        if m := JOB_END.search(line):
            finished.append(m.group(1))
        m = JOB_START.match(line)
        if m:
            started.append(m.group(1))
            if instant is not None and kill_at is None and m.group(1) == instant.rule:
                kill_at = time.monotonic() + instant.delay_s
    if not killed:
        proc.wait(timeout=60)
    while True:  # the rest of what it printed, for diagnostics
        try:
            line = lines.get(timeout=1)
        except queue.Empty:
            break
        if line is None:
            break
        out.append(line)
    running = sorted({r for r in started if started.count(r) > finished.count(r)} - {"all"})
    return Outcome(killed, None if killed else proc.returncode, started, running, "".join(out))


def _kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL to Snakemake and every job it started (one process group), then wait until none is left."""
    pgid = proc.pid
    try:
        os.killpg(pgid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(timeout=60)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.05)
    raise RuntimeError(f"processes of group {pgid} survived SIGKILL")


def recover(workdir: Path, configfile: Path) -> None:
    """The documented recovery's first step: ``snakemake --unlock`` with the same arguments (a killed Snakemake
    leaves its lock; without this the next start stops with "Directory cannot be locked")."""
    args = [a for a in snakemake_args(workdir, configfile) if a != "all"]
    proc = subprocess.run([sys.executable, "-m", "snakemake", "--unlock", *args], cwd=REPO, capture_output=True,
                          text=True, timeout=300)  # fmt: skip
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]


def marked_incomplete(workdir: Path) -> set[Path]:
    """The outputs Snakemake recorded as started and not finished (``.snakemake/incomplete``: each record's path,
    split into parts of at most 255 characters with '@' before all but the last, is the urlsafe base64 of the
    output's path)."""
    root = workdir / ".snakemake" / "incomplete"
    out: set[Path] = set()
    if not root.is_dir():
        return out
    for dirpath, _, files in os.walk(root):
        rel = Path(dirpath).relative_to(root).parts
        for name in files:
            if name == "migration_underway":
                continue
            encoded = "".join(p.lstrip("@") for p in (*rel, name))
            out.add(Path(base64.urlsafe_b64decode(encoded.encode()).decode()))
    return out


def _covered(rel: Path, incomplete: set[Path]) -> bool:
    return any(rel == p or p in rel.parents for p in incomplete)


def is_temporary(path: Path) -> bool:
    """A temporary of :func:`eigs.util.atomic.atomic_path` (or a file inside one): never read by a job."""
    return any(ANY_TEMPORARY.fullmatch(part) for part in path.parts)


def check_file(path: Path) -> str | None:
    """Open ``path`` with a reader of its type and read all of it; the problem in one line, or None."""
    suffix = path.suffix.lower()
    try:
        if path.name == ".snakemake_timestamp":
            return None
        if suffix == ".h5":
            import h5py

            with h5py.File(path, "r") as f:
                f.visititems(lambda _, obj: obj[()] if isinstance(obj, h5py.Dataset) else None)
        elif suffix == ".ply":
            from plyfile import PlyData

            ply = PlyData.read(str(path))
            if not len(ply["vertex"].data):
                return "no vertices"
        elif suffix == ".json":
            json.loads(path.read_text())
        elif suffix == ".csv":
            rows = list(csv.reader(path.open(newline="")))
            if not rows or any(len(r) != len(rows[0]) for r in rows):
                return "empty, or rows of different lengths"
        elif suffix in (".md", ".tex", ".txt"):
            if not path.read_text(encoding="utf-8").strip():
                return "empty"
        elif suffix == ".png":
            from PIL import Image

            with Image.open(path) as im:
                im.load()
        elif suffix == ".mp4":
            from eigs.view.video import probe_mp4

            if probe_mp4(path)["frames"] < 1:
                return "no frames"
        elif suffix == ".npz":
            import numpy as np

            with np.load(path) as z:
                for k in z.files:
                    z[k]
        elif suffix == ".bin":
            import pycolmap

            pycolmap.Reconstruction(str(path.parent))
        elif suffix == ".pt":
            import torch

            torch.load(path, map_location="cpu", weights_only=False)
        else:
            return f"no reader for {suffix or 'a file without suffix'} in the check (add one)"
    except Exception as err:  # any reader's complaint is the finding
        return f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"
    return None


def check_results(workdir: Path) -> tuple[list[str], list[Path]]:
    """Every file under ``results/``: (problems of files neither marked incomplete nor readable, temporaries left).
    A problem is a partial file that a later job would take for a finished one."""
    incomplete = marked_incomplete(workdir)
    problems: list[str] = []
    temps: list[Path] = []
    for path in sorted((workdir / "results").rglob("*")):
        rel = path.relative_to(workdir)
        if is_temporary(rel):
            if ANY_TEMPORARY.fullmatch(path.name):
                temps.append(rel)
            continue
        if path.is_dir() or _covered(rel, incomplete):
            continue
        problem = check_file(path)
        if problem:
            problems.append(f"{rel}: {problem}")
    return problems, temps


def final_figures(workdir: Path) -> dict[str, object]:
    """What the tables and evaluations say, without the wall-time figures (those differ between two uninterrupted
    runs too): every table CSV without its timing columns, every metrics.json without its timings."""
    out: dict[str, object] = {}
    for path in sorted((workdir / "results" / "tables").glob("*.csv")):
        rows = list(csv.reader(path.open(newline="")))
        keep = [i for i, name in enumerate(rows[0]) if not TIMING_COLUMNS.match(name)]
        out[str(path.relative_to(workdir))] = [[r[i] for i in keep] for r in rows]
    for path in sorted((workdir / "results").glob("*/b*/eval/*/metrics.json")):
        doc = json.loads(path.read_text())
        for key in ("train_seconds", "fps", "render_ms", "frames_timed"):
            doc.pop(key, None)
        out[str(path.relative_to(workdir))] = doc
    return out


def stage_durations(workdir: Path) -> dict[str, float]:
    """Seconds of each stage's shortest job in a finished run, by benchmark name (``benchmarks/<stage>/*.tsv`` or
    ``benchmarks/<stage>.tsv``, as the rules write them: the SfM rules share ``sfm``)."""
    out: dict[str, float] = {}
    for tsv in (workdir / "benchmarks").rglob("*.tsv"):
        rows = list(csv.DictReader(tsv.open(), delimiter="\t"))
        if rows:
            stage = tsv.stem if tsv.parent.name == "benchmarks" else tsv.parent.name
            out[stage] = min(out.get(stage, float("inf")), float(rows[-1]["s"]))
    return out
