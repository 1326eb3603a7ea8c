"""The evaluation / tables part of the DAG for every config: dry runs (config.yaml's job counts, e2nerf.yaml against a
layout made by the synthetic-scene exporter, real.yaml when ../shared is present), config runs that exist in the
method registry, table rows that name configured runs, and the toy DAG end to end."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from eigs.tables.rows import OPTIONAL_TABLES, table_rows
from eigs.train.catalog import method_names
from tests.conftest import SHARED_REAL, require

REPO = Path(__file__).resolve().parents[1]
CONFIGS = sorted((REPO / "config").glob("*.yaml"))


def snakemake(*args: str, cwd: Path = REPO, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True, text=True,
                          check=False, timeout=timeout)  # fmt: skip


def job_counts(out: str) -> dict[str, int]:
    block = out.split("Job stats:")[1].split("total")[0]
    return {m.group(1): int(m.group(2)) for m in re.finditer(r"^(\w+)\s+(\d+)$", block, re.M)}


@pytest.mark.parametrize("path", CONFIGS, ids=lambda p: p.name)
def test_config_runs_use_registered_methods(path):
    runs = yaml.safe_load(path.read_text()).get("runs", {})
    assert runs, path
    for name, spec in runs.items():
        assert spec["method"] in method_names(), f"{path.name}: run {name} uses unknown method {spec['method']}"


@pytest.mark.parametrize("name", ["config.yaml", "e2nerf.yaml"])
def test_full_suites_fill_every_table_row_they_can(name):
    """In the full suites every row of Tables I-V names a configured run (or null: paper values only), and every
    configured run appears in some table (the optional ladder table has its runs in config/ladder.yaml)."""
    cfg = yaml.safe_load((REPO / "config" / name).read_text())
    runs = cfg["runs"]
    tables = table_rows(cfg.get("tables"))
    used = set()
    for table, rows in tables.items():
        for row, run in rows.items():
            assert run is None or run in runs or table in OPTIONAL_TABLES, f"{name}: {table}.{row} -> {run}"
            used.add(run)
    assert set(runs) <= used, f"{name}: runs in no table: {sorted(set(runs) - used)}"


def test_default_config_schedules_every_table_variant():
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", "--configfile=config/config.yaml")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    counts = job_counts(proc.stdout)
    # 26 runs on 6 scenes (22 Gaussian, 4 radiance-field), each evaluated; EDI/SfM/init at B = 4, 6, 8; COLMAP at
    # B = 4 only, B = 6 and 8 resampled from it (docs/sfm.md "One SfM per scene")
    assert counts["train"] == 132 and counts["train_field"] == 24 and counts["evaluate"] == 156
    assert counts["edi"] == counts["init"] == 18 and counts["sfm"] == 6 and counts["sfm_resample"] == 12
    assert counts["tables"] == counts["figures"] == 1
    # shared runs are trained once: eigs+ feeds Tables I-V from one folder per scene
    assert proc.stdout.count("output: results/chair/b4/eigs+/model.ply") == 1
    assert "results/chair/b6/eigs-b6/model.ply" in proc.stdout
    assert '"width":64' in proc.stdout


def test_e2nerf_config_dry_runs_on_an_exported_layout(tmp_path):
    """config/e2nerf.yaml with its data root pointed at layouts written by `eigs synth --e2nerf-layout` (synthetic;
    the real scenes get folders only, since no exporter writes the E²NeRF real layout: a dry run checks paths)."""
    data = tmp_path / "data"
    synth = data / "synthetic"
    proc = subprocess.run([sys.executable, "-m", "eigs", "synth", "--scene", "toy", "--e2nerf-layout",
                           str(synth / "chair"), "--threads", "1"], capture_output=True, text=True, check=False,
                          timeout=600)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert (synth / "chair" / "transform_train.json").is_file() and (synth / "chair" / "events.pt").is_file()
    for name in ("ficus", "hotdog", "lego", "materials", "mic"):
        (synth / name).symlink_to(synth / "chair", target_is_directory=True)
    for name in ("letter", "lego", "camera", "plant", "toys"):
        (data / "real-world" / name).mkdir(parents=True)
    text = (REPO / "config" / "e2nerf.yaml").read_text().replace("data/e2nerf/", f"{data}/")
    cfg = tmp_path / "e2nerf.yaml"
    cfg.write_text(text)
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", f"--configfile={cfg}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    counts = job_counts(proc.stdout)
    # 11 scenes ingested; 20 Gaussian runs, oracle only on the 6 synthetic scenes: 19·11 + 6 = 215; 4 field runs:
    # 4·11 = 44
    assert counts["ingest"] == 11 and counts["train"] == 215 and counts["train_field"] == 44
    assert counts["evaluate"] == 215 + 44
    assert "--format e2nerf-synthetic" in proc.stdout and "--format e2nerf-real" in proc.stdout
    assert '"steps":30000' in proc.stdout
    assert '"6":null' in proc.stdout  # Table III's N = 6, 8 rows: paper values only


def test_real_config_dry_runs_when_shared_data_is_present():
    require(SHARED_REAL.is_dir(), f"{SHARED_REAL} is absent")
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", "--configfile=config/real.yaml")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    counts = job_counts(proc.stdout)
    assert counts["ingest"] == 1 and counts["train"] == 2 and counts["evaluate"] == 2
    assert "--path-frames 30" in proc.stdout


def test_toy_dag_end_to_end_produces_the_tables(tmp_path, toy):
    """snakemake all on config/toy.yaml in a scratch directory: synth → … → train (5 runs) → evaluate → tables,
    figures, video. It starts from a copy of the shared toy fixture's folder, where the same workflow ran synth → init
    on the same config (Snakemake's metadata copied with it, so those jobs are up to date, not rerun). Records the
    toy Table I (EiGS against 3DGS) in the test output."""
    shutil.copytree(toy.root, tmp_path, dirs_exist_ok=True, ignore=shutil.ignore_patterns("locks", "DONE"))
    cmd = [sys.executable, "-m", "snakemake", "all", "--cores", "2", "-s", str(REPO / "workflow" / "Snakefile"),
           "--directory", str(tmp_path), f"--configfile={REPO / 'config' / 'toy.yaml'}"]  # fmt: skip
    # its own process group, so a timeout stops the running jobs too (no orphaned training processes)
    proc = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)  # fmt: skip
    try:
        out, err = proc.communicate(timeout=3600)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)
        out, err = proc.communicate()
        pytest.fail("the toy DAG took more than an hour:\n" + out[-2000:] + err[-2000:])
    assert proc.returncode == 0, out[-3000:] + err[-3000:]
    assert "rule synth:" not in out + err and "rule train:" in out + err  # the upstream was reused
    tables = tmp_path / "results" / "tables"
    for i in range(1, 6):
        for ext in ("csv", "md", "tex"):
            assert (tables / f"table{i}.{ext}").stat().st_size > 0
    for fig in ("qualitative_toy.png", "curves.png", "pareto.png"):
        assert (tmp_path / "results" / "figures" / fig).stat().st_size > 0
    rows = {r["row"]: r for r in csv.DictReader((tables / "table1.csv").open())}
    assert rows["oracle"]["role"] == "oracle" and rows["oracle"]["psnr_rank"] == ""
    assert rows["eigs"]["source"] == "results/toy/b4/eigs" and rows["eigs"]["psnr_paper"] == "28.21"
    doc = json.loads((tmp_path / "results/toy/b4/eval/eigs/metrics.json").read_text())
    assert float(rows["eigs"]["psnr"]) == pytest.approx(doc["metrics"]["novel"]["psnr"], abs=1e-12)
    psnr = {row: float(rows[row]["psnr"]) for row in ("3dgs", "edi-3dgs", "eigs", "eigs+", "oracle")}
    print("toy Table I novel PSNR: " + ", ".join(f"{row} {value:.2f}" for row, value in psnr.items()))
    # the suite's story at the toy's budgets (config/toy.yaml; docs/evaluation.md "The toy's budgets", measured:
    # 3dgs 22.56, eigs 27.05, edi-3dgs 28.53, eigs+ 28.93): EiGS above 3DGS, eigs+ above 3DGS on the EDI frames
    assert psnr["eigs"] > psnr["3dgs"]
    assert psnr["eigs+"] > psnr["edi-3dgs"] > psnr["3dgs"]
