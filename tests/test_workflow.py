"""The Snakemake workflow: config validation, dry runs of the whole DAG, lint."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def snakemake(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True, text=True, check=False, timeout=600
    )


@pytest.mark.parametrize("config", ["config/config.yaml", "config/toy.yaml"])
def test_dry_run_whole_dag(config):
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", f"--configfile={config}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "synth" in proc.stdout


def test_configfile_replaces_the_default_config():
    """--configfile=config/toy.yaml must not be merged into config/config.yaml's six scenes."""
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", "--configfile=config/toy.yaml")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "results/toy/scene.h5" in proc.stdout
    assert "results/blocks/" not in proc.stdout


def test_lint_clean():
    proc = snakemake("--lint")
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_invalid_config_is_rejected(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("scenes:\n  x: {format: h5}\n")
    proc = snakemake("all", "-n", "--cores", "1", f"--configfile={bad}")
    assert proc.returncode != 0
    assert "ValidationError" in proc.stderr + proc.stdout or "validat" in (proc.stderr + proc.stdout).lower()


def test_builtin_and_ingested_scenes_do_not_clash(tmp_path):
    """Each results/<scene>/scene.h5 is claimed by exactly one rule (synth or ingest)."""
    src = tmp_path / "data"
    src.mkdir()
    cfg = tmp_path / "mixed.yaml"
    cfg.write_text(f"scenes:\n  toy: {{builtin: toy}}\n  mine: {{source: {src}, format: txt}}\n")
    proc = snakemake("all", "-n", "--forceall", "--cores", "1", f"--configfile={cfg}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "AmbiguousRuleException" not in proc.stderr
