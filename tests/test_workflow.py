"""The Snakemake workflow: config validation, dry runs of the whole DAG, lint."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]


def snakemake(*args: str, cwd: Path = REPO) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "snakemake", *args], cwd=cwd, capture_output=True, text=True, check=False, timeout=600
    )


def job_counts(stdout: str) -> dict[str, int]:
    """The ``Job stats`` table of a dry run as {rule: count}."""
    lines = stdout.split("Job stats:", 1)[1].strip().splitlines()[2:]
    counts: dict[str, int] = {}
    for line in lines:
        parts = line.split()
        if len(parts) != 2 or not parts[1].isdigit():
            break
        counts[parts[0]] = int(parts[1])
    return counts


@pytest.mark.parametrize("config", ["config/config.yaml", "config/toy.yaml"])
def test_dry_run_whole_dag(config):
    """The dry run plans exactly one job per scene (and per configured bin count) for each upstream stage,
    counted independently from the YAML file."""
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", f"--configfile={config}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    cfg = yaml.safe_load((REPO / config).read_text())
    scenes = cfg["scenes"]
    n_bins = len(cfg.get("edi", {}).get("bins", [4]))
    builtin = sum("builtin" in s for s in scenes.values())
    ingested = sum("source" in s for s in scenes.values())
    counts = job_counts(proc.stdout)
    expected = {"synth": builtin, "ingest": ingested, "edi": len(scenes) * n_bins, "init": len(scenes) * n_bins}
    assert {k: counts.get(k, 0) for k in expected} == expected, proc.stdout
    # one SfM job per scene and B: COLMAP, or given poses on built-in scenes that allow them (test_workflow_skips.py),
    # or at B other than the first a COLMAP scene's first-B SfM resampled (tests/sfm/test_resample.py)
    sfm_jobs = counts.get("sfm", 0) + counts.get("sfm_given", 0) + counts.get("sfm_resample", 0)
    assert sfm_jobs == expected["init"], proc.stdout
    assert counts["all"] == 1 and counts["total"] == sum(v for k, v in counts.items() if k != "total")


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


def test_every_ingest_format_plans(tmp_path):
    """A config naming each format `eigs ingest` reads plans under `snakemake -n` (one ingest job per scene); a format
    it does not read fails the dry run on one line naming the scene, the value and the accepted formats."""
    from eigs.ingest import FORMATS

    assert len(FORMATS) == 9
    scenes = {}
    for fmt in FORMATS:
        source = tmp_path / f"rec-{fmt}"
        source.write_bytes(b"")  # a dry run never reads it
        scenes[f"s-{fmt}"] = {"source": str(source), "format": fmt, "options": ["--intrinsics", "60,60,32,24"]}
    cfg = tmp_path / "all_formats.yaml"
    cfg.write_text(yaml.safe_dump({"scenes": scenes, "threads": 1, "runs": {"3dgs": {"method": "3dgs"}}}))
    proc = snakemake("all", "-n", "--cores", "1", f"--configfile={cfg}", "--directory", str(tmp_path))
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    counts = job_counts(proc.stdout)
    assert counts["ingest"] == 9 and counts["train"] == 9, counts
    for fmt in FORMATS:
        assert f"--format {fmt} --name s-{fmt}" in proc.stdout

    scenes["s-bad"] = {"source": str(tmp_path / "rec-h5"), "format": "hdf5"}
    cfg.write_text(yaml.safe_dump({"scenes": scenes, "threads": 1}))
    proc = snakemake("all", "-n", "--cores", "1", f"--configfile={cfg}", "--directory", str(tmp_path))
    assert proc.returncode != 0
    line = f"config: scene s-bad: format 'hdf5' is not one `eigs ingest` reads ({', '.join(FORMATS)})"
    assert line in proc.stdout + proc.stderr


def test_schema_cannot_drift_from_the_ingest_formats():
    """The schema types `format` but lists no formats: the list lives in eigs.ingest.FORMATS alone (the CLI's choices
    and the planner's check read it), so a format added to the code is accepted by the workflow at once."""
    from eigs.ingest import FORMATS
    from eigs.ingest.cli import add_arguments

    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
    ingested = schema["properties"]["scenes"]["additionalProperties"]["oneOf"][1]["properties"]
    assert ingested["format"]["type"] == "string" and "enum" not in ingested["format"]
    assert "eigs.ingest.FORMATS" in ingested["format"]["description"]
    import argparse

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    choices = next(a.choices for a in parser._actions if a.dest == "format")
    assert tuple(choices) == FORMATS
    readme = (REPO / "config" / "README.md").read_text()
    assert all(f"`{fmt}`" in readme for fmt in FORMATS), "config/README.md: the scenes paragraph lists every format"


def test_builtin_and_ingested_scenes_do_not_clash(tmp_path):
    """Each results/<scene>/scene.h5 is claimed by exactly one rule (synth or ingest)."""
    src = tmp_path / "data"
    src.mkdir()
    cfg = tmp_path / "mixed.yaml"
    cfg.write_text(f"scenes:\n  toy: {{builtin: toy}}\n  mine: {{source: {src}, format: txt}}\n")
    proc = snakemake("all", "-n", "--forceall", "--cores", "1", f"--configfile={cfg}")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "AmbiguousRuleException" not in proc.stderr


@pytest.mark.parametrize(
    ("options", "key", "accepted"),
    [({"method_options": {"lamda_event": 1}}, "lamda_event", "accepted: ade, shape,"),
     ({"stepz": 5}, "stepz", "accepted: method, steps,")],
)  # fmt: skip
def test_a_typo_in_a_run_option_fails_the_dry_run_on_one_line(tmp_path, options, key, accepted):
    """Every `runs:` entry is checked while the DAG is planned (eigs.train.resolve.check_runs, rules/common.smk)."""
    cfg = tmp_path / "typo.yaml"
    cfg.write_text(yaml.safe_dump({"scenes": {"toy": {"builtin": "toy"}},
                                   "runs": {"my-eigs": {"method": "eigs", "options": options}}}))  # fmt: skip
    proc = snakemake("all", "-n", "--cores", "1", f"--configfile={cfg}")
    assert proc.returncode != 0
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if key in line]
    assert any("run my-eigs" in line and accepted in line for line in lines), proc.stdout + proc.stderr
