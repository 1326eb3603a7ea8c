"""`make demo` (config/demo.yaml): one scene of the default suite with the four runs that tell the story, at the
suite's budgets, planned through the table, the qualitative grid and the orbit video. Dry runs only (the demo
itself trains for minutes)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import yaml

from tests.test_workflow import job_counts, snakemake

REPO = Path(__file__).resolve().parents[1]
STORY = {"3dgs", "edi-3dgs", "eigs+", "oracle"}


def _config(name: str) -> dict:
    return yaml.safe_load((REPO / "config" / name).read_text())


def test_demo_is_one_suite_scene_with_the_suites_runs():
    """The demo's scene, EDI/SfM settings and runs are the suite's (anchors resolved), so its numbers are the suite's
    chair numbers."""
    demo, suite = _config("demo.yaml"), _config("config.yaml")
    assert list(demo["scenes"]) == ["chair"] and demo["scenes"]["chair"] == suite["scenes"]["chair"]
    assert set(demo["runs"]) == STORY
    for run in STORY:
        assert demo["runs"][run] == suite["runs"][run], run
    for key in ("threads", "sfm"):
        assert demo[key] == suite[key], key
    assert demo["edi"]["bins"] == suite["edi"]["bins"][:1]


def test_demo_dry_run_plans_table_grid_and_video():
    proc = snakemake("all", "-n", "--forceall", "--cores", "2", "--configfile=config/demo.yaml")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    counts = job_counts(proc.stdout)
    expected = {"resources": 1, "synth": 1, "edi": 1, "sfm": 1, "init": 1, "train": 4, "evaluate": 4, "tables": 1,
                "figures": 1, "video": 1, "all": 1}  # fmt: skip
    assert {k: v for k, v in counts.items() if k != "total"} == expected, proc.stdout
    for out in ("results/tables/table1.md", "results/figures/qualitative_chair.png", "results/videos/chair.mp4"):
        assert out in proc.stdout, out
    video = next(ln for ln in proc.stdout.splitlines() if ln.startswith("Shell command: eigs video"))
    runs = [a.rsplit("/", 1)[1] for a in video.split() if a.startswith("results/chair/b4/")]
    assert runs == ["3dgs", "edi-3dgs", "eigs+", "oracle"], video  # Table I's order


def test_make_demo_runs_the_demo_config_with_eigs_plus_first():
    out = subprocess.run(["make", "-n", "-W", "pyproject.toml", "demo"], cwd=REPO, capture_output=True, text=True,
                         check=True, timeout=60).stdout  # fmt: skip
    line = next(ln for ln in out.splitlines() if "snakemake all" in ln)
    assert "--configfile=config/demo.yaml" in line and "--prioritize results/chair/b4/eigs+/model.ply" in line
    assert "--cores 2" in line
