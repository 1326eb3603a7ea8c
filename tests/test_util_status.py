"""`eigs status` on log snippets copied from a real run of the default suite (tests/status_logs/; one resumed
training run written in the loop's format, since no real log had one)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from eigs.cli import main
from eigs.util.status import format_status, read_jobs, select

LOGS = Path(__file__).parent / "status_logs"
NOW = 1_800_000_000.0
# seconds since each log was last written; the jobs with a benchmark file (newer than the log) are done
AGES = {
    "resources.log": 7200,
    "evaluate/blocks_b4_bad-gaussians.log": 1500,
    "sfm/drums-noisy_b4.log": 620,
    "train/dish_b4_besplat.log": 300,
    "sfm/drums_b4.log": 75,
    "edi/blocks_b4.log": 4,
    "train/spheres_b4_besplat.log": 3,
    "train/chair_b4_eigs+.log": 1,
}
DONE = ("resources.log", "evaluate/blocks_b4_bad-gaussians.log", "train/dish_b4_besplat.log")

EXPECTED = """\
8 jobs in logs/: 4 running, 1 failed, 3 done
evaluate  blocks b4 bad-gaussians  done     25m00s ago  wrote results/blocks/b4/eval/bad-gaussians/metrics.json (blur: …
sfm       drums-noisy b4           failed   10m20s ago  eigs sfm: error: results/drums-noisy/b4/sfm: only 43 of 120 lat…
train     dish b4 besplat          done      5m00s ago  step 375/375 (100%), held-out PSNR novel 22.92 dB (final)
sfm       drums b4                 running   1m15s ago  phase matching
edi       blocks b4                running      4s ago  edi: bin events 19/24
train     spheres b4 besplat       running      3s ago  step 127/375 (33%), held-out PSNR novel 19.11 dB (step 125)
train     chair b4 eigs+           running      1s ago  step 1125/1750 (64%), held-out PSNR novel 30.12 dB (step 1125)
"""


def workflow_dir(tmp_path: Path) -> Path:
    """A workflow directory with the snippets as its logs/ and benchmark files for the jobs in DONE."""
    shutil.copytree(LOGS, tmp_path / "logs")
    for rel, age in AGES.items():
        os.utime(tmp_path / "logs" / rel, (NOW - age, NOW - age))
    for rel in DONE:
        bench = (tmp_path / "benchmarks" / rel).with_suffix(".tsv")
        bench.parent.mkdir(parents=True, exist_ok=True)
        bench.write_text("s\th:m:s\n1.0\t0:00:01\n")
        os.utime(bench, (NOW - AGES[rel] + 1, NOW - AGES[rel] + 1))
    return tmp_path


def test_status_lines_from_real_logs(tmp_path):
    jobs = read_jobs(workflow_dir(tmp_path), now=NOW)
    assert sorted(str(p.relative_to(LOGS)) for p in LOGS.rglob("*.log")) == sorted(AGES)
    assert format_status(jobs, select(jobs, recent=2), width=120) + "\n" == EXPECTED


def test_every_job_and_a_rerun(tmp_path):
    d = workflow_dir(tmp_path)
    jobs = read_jobs(d, now=NOW)
    assert [j.state for j in jobs] == ["done", "done", "failed", "done", "running", "running", "running", "running"]
    assert (jobs[0].stage, jobs[0].name, jobs[0].progress) == (
        "resources", "", "brisque_opencv: resources/brisque_opencv is up to date")  # fmt: skip
    # a finished job started again: its log is newer than its benchmark file, so it runs
    log = d / "logs/train/dish_b4_besplat.log"
    os.utime(log, (NOW, NOW))
    assert next(j for j in read_jobs(d, now=NOW) if j.name == "dish b4 besplat").state == "running"


def test_cli(tmp_path, capsys):
    d = workflow_dir(tmp_path)
    assert main(["status", "--directory", str(d), "--recent", "0"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "8 jobs in logs/: 4 running, 1 failed, 3 done"
    assert [line.split()[0] for line in out[1:]] == ["sfm", "sfm", "edi", "train", "train"]
    assert main(["status", "--directory", str(tmp_path / "nowhere")]) == 2
    assert "no logs/ here" in capsys.readouterr().err
