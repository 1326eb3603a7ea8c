"""The workflow's `bench` target (rules/bench.smk), on dry runs: not part of `all`; every bench script once; the full
mode regenerates docs/benchmarks.md, the quick mode writes results/bench/benchmarks.md and leaves docs/ alone; the
option is validated. And the Pareto front of bench/report.py against its definition, and its skips table (the
`events: false` row) with its figure from small measurements."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench.report import pareto, skips, train_steps

REPO = Path(__file__).resolve().parents[1]
SCRIPTS = {"edi", "ingest", "rasterizer", "sfm", "synth"}  # bench_script jobs (metrics and train: own rules)


def dry_run(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "snakemake", *args, "-n", "-p", "--forceall", "--cores", "2", "-s",
           str(REPO / "workflow" / "Snakefile"), "--directory", str(tmp_path),
           f"--configfile={REPO / 'config' / 'toy.yaml'}"]  # fmt: skip
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, check=False, timeout=300)


def outputs(stdout: str) -> list[str]:
    return [p for line in stdout.splitlines() if line.strip().startswith("output: ")
            for p in line.strip().removeprefix("output: ").split(", ")]  # fmt: skip


def test_all_runs_no_benchmark(tmp_path):
    proc = dry_run(tmp_path, "all")
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert not re.search(r"^rule bench", proc.stdout, re.M)
    assert not any(o.startswith("results/bench") or o.startswith("docs/") for o in outputs(proc.stdout))


@pytest.mark.parametrize("quick", [False, True])
def test_bench_runs_every_script_once_and_writes_one_report(tmp_path, quick):
    proc = dry_run(tmp_path, "bench", *(["--config", "bench_quick=1"] if quick else []))
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = outputs(proc.stdout)
    assert {o for o in out if re.fullmatch(r"results/bench/[\w-]+\.json", o)} == {
        f"results/bench/{n}.json"
        for n in SCRIPTS | {"metrics", "train-step", "train-step-methods", "train-step-malloc"}
    }
    doc = "results/bench/benchmarks.md" if quick else "docs/benchmarks.md"
    figures = "results/bench/figures" if quick else "docs/figures"
    assert doc in out and ("docs/benchmarks.md" in out) == (not quick)
    assert {f"{figures}/bench_{n}.png" for n in ("edi", "sfm", "rasterizer", "train", "skips")} <= set(out)
    commands = [ln for ln in proc.stdout.splitlines() if ln.startswith("Shell command:") and "bench/" in ln]
    assert len(commands) == len(SCRIPTS) + 3  # the scripts, metrics, train, report
    assert all(("--quick" in c or "--events 2000000" in c or "--scenes" in c or " toy " in c) == quick
               for c in commands if "report.py" not in c)  # fmt: skip
    # the training-step benchmark trains on the configured scene's artifacts, made by the workflow's own jobs
    assert "--results results/toy --bins 4" in proc.stdout and "rule sfm_given:" in proc.stdout


def test_bench_quick_is_validated(tmp_path):
    proc = dry_run(tmp_path, "bench", "--config", "bench_quick=2")
    assert proc.returncode != 0 and "bench_quick" in proc.stdout + proc.stderr


def test_pareto_front_against_its_definition():
    """A point is on the front iff no other point is at most as large in both coordinates and smaller in one."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        pts = [tuple(map(float, p)) for p in rng.integers(0, 8, (int(rng.integers(1, 12)), 2))]
        pts = list(dict.fromkeys(pts))
        expect = sorted(p for p in pts if not any(q[0] <= p[0] and q[1] <= p[1] and q != p for q in pts))
        assert pareto(pts) == expect, pts


def test_skips_table_counts_edi_and_the_event_runs_training_of_a_scene_without_events(tmp_path):
    """The `events: false` row: an `edi_frames` job instead of `edi` and the event runs not scheduled; the time saved
    per scene is the EDI time plus each event run's step time × its steps; the figure is written."""
    import json

    (tmp_path / "edi.json").write_text(json.dumps({"data": {"runtime_error": [
        {"bins": 4, "mode": "estimated", "time_s": 3.0}]}}))  # fmt: skip
    methods = [{"method": "3dgs", "step_ms": 10.0}, {"method": "eigs", "step_ms": 100.0},
               {"method": "e2gs", "step_ms": 50.0}]  # fmt: skip
    (tmp_path / "train-step-methods.json").write_text(json.dumps({"data": {"methods": methods}}))
    facts = {"frames_only": 1, "train_jobs": 5, "upstream_jobs": 2,
             "event_runs": {"eigs": {"method": "eigs", "steps": 20}, "e2gs": {"method": "e2gs", "steps": None}}}
    fig = tmp_path / "bench_skips.png"
    md = skips(tmp_path, facts, fig)
    line = next(ln for ln in md.splitlines() if "events: false" in ln)
    assert "`edi_frames`" in line and "`e2gs`, `eigs`" in line and "not scheduled" in line
    steps = train_steps()  # a run without `steps`: eigs.train.config.TrainConfig's
    assert f"{3.0 + 100.0 / 1e3 * 20 + 50.0 / 1e3 * steps:.3g} s per scene" in line
    assert fig.stat().st_size > 0
