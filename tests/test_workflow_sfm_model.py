"""An existing COLMAP model as the poses (issue 33 part 5) in the workflow: `sfm: {mode: model, path: …}`, global
or per scene, schedules an `sfm_model` job (`eigs sfm --mode model`) instead of the COLMAP `sfm` job or
`sfm_given`, visible in a dry run; the model directory is the job's input."""

from __future__ import annotations

import re

from tests.test_workflow_skips import job_counts, snakemake


def _commands(out: str) -> list[str]:
    return [ln for ln in out.splitlines() if ln.startswith("Shell command: eigs sfm ")]


def test_per_scene_model_skips_colmap(tmp_path):
    """A built-in and an ingested scene with a per-scene model beside a built-in scene without one: two
    `sfm_model` jobs reading their model directories, one `sfm_given`, no COLMAP job."""
    for d in ("models/a", "models/mine"):
        (tmp_path / d).mkdir(parents=True)
    src = tmp_path / "events.txt"
    src.write_text("0 1 1 1\n")
    cfg = {"scenes": {"a": {"builtin": "toy", "sfm": {"mode": "model", "path": "models/a"}},
                      "b": {"builtin": "toy"},
                      "mine": {"source": str(src), "format": "txt",
                               "sfm": {"mode": "model", "path": "models/mine", "intrinsics_tolerance": 0.02}}},
           "threads": 1}  # fmt: skip
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert counts.get("sfm_model") == 2 and counts.get("sfm_given") == 1 and "sfm" not in counts, proc.stdout
    model = [c for c in _commands(proc.stdout) if "--mode model" in c]
    assert len(model) == 2
    assert any("--model models/a " in c and "results/a/" in c for c in model)
    mine = next(c for c in model if "results/mine/" in c)
    assert "--model models/mine " in mine and '"intrinsics_tolerance":0.02' in mine and '"mode":"model"' in mine


def test_global_model_with_scene_placeholder(tmp_path):
    """A global `sfm: {mode: model, path: models/{scene}}` applies to every scene, each with its own directory."""
    for d in ("models/a", "models/b"):
        (tmp_path / d).mkdir(parents=True)
    cfg = {"scenes": {"a": {"builtin": "toy"}, "b": {"builtin": "toy"}}, "threads": 1,
           "sfm": {"mode": "model", "path": "models/{scene}"}}  # fmt: skip
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", "-p", "--forceall")
    counts = job_counts(proc.stdout)
    assert counts.get("sfm_model") == 2 and "sfm_given" not in counts and "sfm" not in counts
    assert sorted(re.findall(r"--model (models/\w)", proc.stdout)) == ["models/a", "models/b"]


def test_model_mode_config_errors(tmp_path):
    """Mode model without a path is a config error naming the scene; a missing model directory is a missing input."""
    cfg = {"scenes": {"a": {"builtin": "toy", "sfm": {"mode": "model"}}}, "threads": 1}
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", ok=False)
    assert "scene a: sfm mode model needs `path`" in proc.stdout + proc.stderr
    cfg = {"scenes": {"a": {"builtin": "toy", "sfm": {"mode": "model", "path": "models/none"}}}, "threads": 1}
    proc = snakemake(tmp_path, cfg, "all_sfm", "-n", "--forceall", ok=False)
    assert "models/none" in proc.stdout + proc.stderr and "Missing input" in proc.stdout + proc.stderr
